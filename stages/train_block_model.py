"""DVC stage: train the block model that `sampled_lookahead` draws its imagined maps from.

Reads only the `train_block_model` section (mazes, holdout_mazes, side_m, maze_seed,
snapshot_every, epochs, batch_size, lr, reveal_share, model, workers, seed) and the shared
`protocol` section of params.yaml. Draws its own `mazes` mazes of `side_m` metres (maze i from
seed [maze_seed, i], as `guide mazes` draws them): the block model is a prior of one maze
family and size, and one fitted on the pipeline's 100-180 m training mazes was weaker on the
100 m test mazes. Runs gated `greedy_utility` on each, takes the
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

from pydantic import model_validator

from pipeline.common.config import Section, fraction, positive, real, whole
from pipeline.models.configuration_block_model import BlockModelConfig
from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.train_block_model import maze_config, train_the_block_model
from pipeline.world.protocol import Protocol


class Settings(Section):
    """The `train_block_model` section of params.yaml."""

    mazes: whole(1)
    holdout_mazes: whole(0)
    side_m: positive("metres")
    maze_seed: whole(0)
    snapshot_every: whole(1, note="steps")
    epochs: whole(1)
    batch_size: whole(1)
    lr: real(0.0)
    reveal_share: fraction()
    model: BlockModelConfig
    workers: whole(1)
    seed: whole(0)

    @model_validator(mode="after")
    def _holdout_leaves_mazes_to_fit(self) -> "Settings":
        if not self.holdout_mazes < self.mazes:
            raise ValueError(f"holdout_mazes ({self.holdout_mazes}) must be below mazes ({self.mazes})")
        return self


def read_params(params_path: str | Path) -> tuple[dict[str, Any], BlockModelConfig, Protocol]:
    """The section, its model config and the protocol; a maze size the protocol cannot draw is
    refused by `side_m` before any episode runs."""
    section = read_stage(params_path, "train_block_model", Settings)
    config = BlockModelConfig.from_dict(section["model"])
    protocol = read_protocol(params_path)
    try:
        maze_config(section, config, protocol)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{params_path}: train_block_model.side_m: {error}") from None
    return section, config, protocol


def main(params_path: str = "params.yaml") -> dict[str, Any]:
    """Collect, train, measure and write the block model; returns the metrics written."""
    section, config, protocol = read_params(params_path)
    metrics = train_the_block_model(section, config, protocol)
    print(json.dumps({k: v for k, v in metrics.items() if k != "history"}, indent=2))
    return metrics


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
