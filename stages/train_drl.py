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
from pipeline.common.settings import (AnyOf, Fields, Flag, ListOf, Maybe, Real, Satisfies, Text, Whole, check_stage,
                                      config_mapping, fraction, keys_of, positive)
from pipeline.models.configuration_drl import DRLPolicyConfig
from pipeline.planners import planner_config
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.training.drl import PPOSettings, TrainingEnvironment
from pipeline.training.drl_imitation import ImitationSettings
from pipeline.workflows.train_drl import train_the_drl_policy
from pipeline.world.protocol import Protocol

SETTINGS = Fields({
    "model": config_mapping(DRLPolicyConfig, {"max_nodes": Whole(1), "d_model": Whole(1), "heads": Whole(1),
                                              "encoder_layers": Whole(1), "guidepost_prior": Real(0.0)}),
    "env": Fields({
        "maze_sides_m": AnyOf((ListOf(positive()), positive()), "a non-empty list of maze sides (m), each > 0"),
        "max_steps": Whole(1),
        "area_weight": Real(0.0),
        "distance_weight": Real(0.0),
        "completion_bonus": Real(0.0),
    }),
    "ppo": Fields({
        **{key: Whole(1) for key in ("n_envs", "n_steps", "batch_size", "n_epochs")},
        "learning_rate": positive(), "gamma": fraction(), "gae_lambda": fraction(), "clip_range": positive(),
        "ent_coef": Real(), "vf_coef": Real(), "max_grad_norm": positive(), "subprocess": Flag(),
    }),
    "imitation": Fields({
        "planner": Satisfies(planner_config, "a registered planner name"),
        "episodes": Whole(0, note="0: no warm start"), "epochs": Whole(1), "dagger_rounds": Whole(0),
        "dagger_episodes": Whole(1), "dagger_epochs": Whole(1), "batch_size": Whole(1),
        "learning_rate": positive(), "value_weight": Real(0.0),
    }),
    "init_checkpoint": Maybe(Text(note="a drl export"), "the warm start"),
    "timesteps": Whole(1),
    "checkpoint_every": Whole(1),
    "eval_mazes": Whole(0),
    "eval_side_m": positive("metres"),
    "eval_seed": Whole(0),
    "seed": Whole(0),
    "threads": Whole(0, note="0: torch's default"),
    "device": Text(("cpu", "cuda", "auto")),
    "experiment": Text(note="an MLflow experiment"),
})
KEYS = keys_of(SETTINGS)


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
    check_stage(params_path, "train_drl", SETTINGS)
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
