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

from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.train_block_model import Settings, maze_config, train_the_block_model
from pipeline.world.protocol import Protocol


def read_params(params_path: str | Path) -> tuple[Settings, Protocol]:
    """The settings and the protocol; a maze size the protocol cannot draw is refused by `side_m`
    before any episode runs."""
    settings = read_stage(params_path, "train_block_model", Settings)
    protocol = read_protocol(params_path)
    try:
        maze_config(settings, protocol)
    except (TypeError, ValueError) as error:
        raise ValueError(f"{params_path}: train_block_model.side_m: {error}") from None
    return settings, protocol


def main(params_path: str = "params.yaml") -> dict[str, Any]:
    """Collect, train, measure and write the block model; returns the metrics written."""
    metrics = train_the_block_model(*read_params(params_path))
    print(json.dumps({k: v for k, v in metrics.items() if k != "history"}, indent=2))
    return metrics


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
