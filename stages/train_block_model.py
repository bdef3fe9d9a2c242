"""DVC stage: train the block model that `sampled_lookahead` draws its imagined maps from.

Reads only the `train_block_model` section (mazes, holdout_mazes, side_m, maze_seed,
snapshot_every, epochs, batch_size, lr, reveal_share, model, workers, seed) and the shared
`protocol` section of params.yaml. Draws its own `mazes` mazes of `side_m` metres (maze i from
seed [maze_seed, i], as `guide mazes` draws them): the block model is a prior of one maze
family and size, and one fitted on the pipeline's 100-180 m training mazes was weaker on the
100 m test mazes (docs/findings.md). Runs gated `greedy_utility` on each, takes the
belief's block shares every `snapshot_every` steps with the maze's true blocks, trains the
block model on all but the last `holdout_mazes` and measures its error on those (the unknown
blocks within 20 m of the known free space, where the lookahead draws its maps).
Writes models/block_model/block_model.pt, reports/block_model.json (snapshots, per-epoch loss
and held-out block error) and reports/block_model.png (the curves, and one held-out snapshot:
seen, predicted, true). Logs one MLflow run in experiment "block_model".
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pipeline.common.params import complete_section, load_params
from pipeline.common.settings import Fields, ListOf, Real, Whole, check_stage, config_mapping, fraction, keys_of, positive
from pipeline.models.configuration_block_model import BlockModelConfig
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.train_block_model import maze_config, train_the_block_model
from pipeline.world.protocol import Protocol

SETTINGS = Fields({
    "mazes": Whole(1),
    "holdout_mazes": Whole(0),
    "side_m": positive("metres"),
    "maze_seed": Whole(0),
    "snapshot_every": Whole(1, note="steps"),
    "epochs": Whole(1),
    "batch_size": Whole(1),
    "lr": Real(0.0),
    "reveal_share": fraction(),
    "model": config_mapping(BlockModelConfig, {"width": Whole(1), "dilations": ListOf(Whole(1)), "groups": Whole(1),
                                               "block_m": positive("metres")}),
    "workers": Whole(1),
    "seed": Whole(0),
})
KEYS = keys_of(SETTINGS)


def read_params(params_path: str | Path) -> tuple[dict[str, Any], BlockModelConfig, Protocol]:
    params = load_params(params_path)
    section = complete_section(params, "train_block_model", params_path, KEYS)
    for key in ("mazes", "holdout_mazes", "maze_seed", "snapshot_every", "epochs", "batch_size", "workers", "seed"):
        value = section[key]
        if isinstance(value, bool) or not isinstance(value, int) or value < (0 if key in ("holdout_mazes", "maze_seed", "seed") else 1):
            raise ValueError(f"{params_path}: train_block_model.{key} must be a whole number, got {value!r}")
    if not section["holdout_mazes"] < section["mazes"]:
        raise ValueError(f"{params_path}: train_block_model.holdout_mazes must be below train_block_model.mazes")
    for key, high in (("lr", None), ("reveal_share", 1.0)):
        value = section[key]
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 0 or (high is not None and value > high):
            raise ValueError(f"{params_path}: train_block_model.{key} must be a number in [0, {high or 'inf'}], got {value!r}")
    if not isinstance(section["model"], dict):
        raise ValueError(f"{params_path}: train_block_model.model must be a mapping of BlockModelConfig fields")
    try:
        config = BlockModelConfig.from_dict(section["model"])
    except (TypeError, ValueError) as error:
        raise ValueError(f"{params_path}: train_block_model.model: {error}") from None
    protocol = Protocol.from_dict(params.get("protocol") or {})
    try:
        maze_config(section, config, protocol)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{params_path}: train_block_model.side_m: {error}") from None
    return section, config, protocol


def main(params_path: str = "params.yaml") -> dict[str, Any]:
    """Collect, train, measure and write the block model; returns the metrics written."""
    check_stage(params_path, "train_block_model", SETTINGS)
    section, config, protocol = read_params(params_path)
    metrics = train_the_block_model(section, config, protocol)
    print(json.dumps({k: v for k, v in metrics.items() if k != "history"}, indent=2))
    return metrics


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
