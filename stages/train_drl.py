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

from pipeline.common.params import complete_section, load_params
from pipeline.models.configuration_drl import DRLPolicyConfig
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.training.drl import PPOSettings, TrainingEnvironment
from pipeline.training.drl_imitation import ImitationSettings
from pipeline.workflows.train_drl import train_the_drl_policy
from pipeline.world.protocol import Protocol

KEYS = ("model", "env", "ppo", "imitation", "init_checkpoint", "timesteps", "checkpoint_every", "eval_mazes", "eval_side_m", "eval_seed", "seed",
        "threads", "device", "experiment")


def read_params(params_path: str | Path, timesteps: int | None = None) -> tuple[dict[str, Any], Protocol]:
    params = load_params(params_path)
    section = complete_section(params, "train_drl", params_path, KEYS)
    if timesteps is not None:
        section["timesteps"] = timesteps
    for key, low in (("timesteps", 1), ("checkpoint_every", 1), ("eval_mazes", 0), ("eval_seed", 0), ("seed", 0),
                     ("threads", 0)):
        value = section[key]
        if isinstance(value, bool) or not isinstance(value, int) or value < low:
            raise ValueError(f"{params_path}: train_drl.{key} must be a whole number >= {low}, got {value!r}")
    for group, cls in (("model", DRLPolicyConfig), ("env", TrainingEnvironment), ("ppo", PPOSettings),
                       ("imitation", ImitationSettings)):
        if not isinstance(section[group], dict):
            raise ValueError(f"{params_path}: train_drl.{group} must be a mapping of {cls.__name__} fields")
        try:
            cls.from_dict(section[group])
        except (TypeError, ValueError) as error:
            raise ValueError(f"{params_path}: train_drl.{group}: {error}") from None
    if section["device"] not in ("cpu", "cuda", "auto"):
        raise ValueError(f"{params_path}: train_drl.device must be cpu, cuda or auto, got {section['device']!r}")
    if not isinstance(section["experiment"], str) or not section["experiment"]:
        raise ValueError(f"{params_path}: train_drl.experiment must be an MLflow experiment name")
    protocol = Protocol.from_dict(params.get("protocol") or {})
    init = section["init_checkpoint"]
    if init is not None and (not isinstance(init, str) or not Path(init).is_file()):
        raise ValueError(f"{params_path}: train_drl.init_checkpoint must be null or a drl export file, got {init!r}")
    env = TrainingEnvironment.from_dict(section["env"])
    model = DRLPolicyConfig.from_dict(section["model"])
    checks = [("env", {**env.to_dict(), "maze_sides_m": [side]}) for side in env.maze_sides_m]
    checks += [("eval_side_m", {**env.to_dict(), "maze_sides_m": [section["eval_side_m"]]})]
    for what, values in checks:
        try:
            TrainingEnvironment.from_dict(values).make(0, protocol, model).close()
        except (TypeError, ValueError) as error:
            what = "env.maze_sides_m" if what == "env" and str(error).startswith("maze_side_m") else what
            raise ValueError(f"{params_path}: train_drl.{what}: {error}") from None
    return section, protocol


def main(params_path: str = "params.yaml", timesteps: int | None = None) -> dict[str, Any]:
    """Train (or continue), export and evaluate the drl policy; returns the metrics written."""
    section, protocol = read_params(params_path, timesteps)
    metrics = train_the_drl_policy(section, protocol)
    print(json.dumps({k: v for k, v in metrics.items() if k not in ("history", "evaluation", "host")}, indent=2))
    if metrics["evaluation"]:
        print(json.dumps({k: v for k, v in metrics["evaluation"].items() if k != "episodes"}, indent=2))
    return metrics


if __name__ == "__main__":
    parser = stage_arguments(__doc__)
    parser.add_argument("--timesteps", type=int, default=None,
                        help="train for this many environment steps in all instead of train_drl.timesteps")
    arguments = parser.parse_args()
    run_stage_main(main, arguments.params, arguments.timesteps)
