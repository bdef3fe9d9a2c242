"""DVC stage: train the `drl` baseline (Cao et al. 2024) by MaskablePPO in guide/Explore-v0.

Reads only the `train_drl` section (model, env, ppo, timesteps, checkpoint_every, eval_mazes,
eval_side_m, eval_seed, seed, threads, device, experiment) and the shared `protocol` section of
params.yaml. Trains on fresh generated mazes (the environment draws one per reset), continues
from checkpoints/drl when a killed run left one with the same settings, exports
models/drl/policy.pt, explores `eval_mazes` fresh mazes greedily beside nearest_frontier, and
writes reports/drl_metrics.json and reports/drl_curves.png. Logs one MLflow run.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from pipeline.common.config import check_value, whole
from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.training.drl import TrainingEnvironment
from pipeline.workflows.train_drl import Settings, train_the_drl_policy
from pipeline.world.protocol import Protocol


def read_params(params_path: str | Path, timesteps: int | None = None) -> tuple[Settings, Protocol]:
    """The settings (with `timesteps` from the command line when given) and the protocol; an
    environment the protocol cannot make (a maze side, a reward weight) is refused by its key
    before any training."""
    settings = read_stage(params_path, "train_drl", Settings)
    if timesteps is not None:
        settings = settings.replaced(timesteps=check_value(whole(1), timesteps, "--timesteps"))
    protocol = read_protocol(params_path)
    init = settings.init_checkpoint
    if init is not None and not Path(init).is_file():
        raise ValueError(f"{params_path}: train_drl.init_checkpoint must be null or a drl export file, got {init!r}")
    env = settings.env
    checks = [("env", {**env.to_dict(), "maze_sides_m": [side]}) for side in env.maze_sides_m]
    checks += [("eval_side_m", {**env.to_dict(), "maze_sides_m": [settings.eval_side_m]})]
    for what, values in checks:
        try:
            TrainingEnvironment.from_dict(values).make(0, protocol, settings.model).close()
        except (TypeError, ValueError) as error:
            what = "env.maze_sides_m" if what == "env" and str(error).startswith("maze_side_m") else what
            raise ValueError(f"{params_path}: train_drl.{what}: {error}") from None
    return settings, protocol


def main(params_path: str = "params.yaml", timesteps: int | None = None) -> dict[str, Any]:
    """Train (or continue), export and evaluate the drl policy; returns the metrics written."""
    metrics = train_the_drl_policy(*read_params(params_path, timesteps))
    print(json.dumps({k: v for k, v in metrics.items() if k not in ("history", "evaluation", "host")}, indent=2))
    if metrics["evaluation"]:
        print(json.dumps({k: v for k, v in metrics["evaluation"].items() if k != "episodes"}, indent=2))
    return metrics


if __name__ == "__main__":
    parser = stage_arguments(__doc__)
    parser.add_argument(
        "--timesteps",
        type=int,
        default=None,
        help="train for this many environment steps in all instead of train_drl.timesteps",
    )
    arguments = parser.parse_args()
    run_stage_main(main, arguments.params, arguments.timesteps)
