"""DVC stage: Stage II training of the diffusion planner (one run per variant: guide, dare).

Reads only the `train_planner` section of params.yaml. Trains on the variant's observations and
writes its model folder (policy.pt, the EMA weights for inference; Lightning's last.ckpt and
best.ckpt go to checkpoints/planner_<variant>/, where a killed run resumes from when its settings
and observations are the same), metrics and curves: the paths of `policies` in pipeline/paths.yaml.
"""

from __future__ import annotations

from pipeline.common.params import complete_section, load_params
from pipeline.common.paths import POLICIES
from pipeline.common.settings import (AnyOf, Fields, Flag, ListOf, Maybe, Real, Text, Whole, check_stage, config_mapping,
                                      fraction, keys_of, positive)
from pipeline.models.configuration_diffusion import PREDICTION_TYPES, SAMPLERS, DiffusionPolicyConfig
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.train_planner import train_and_report

VARIANTS = tuple(POLICIES)  # guide, dare
# Lightning's devices: a count, a list of device indices, or a word such as "auto".
DEVICES = AnyOf((Whole(1), Whole(-1, -1), ListOf(Whole(0)), Text(("auto",))),
                "a number of devices >= 1, -1 (all), a list of device indices or 'auto'")
SETTINGS = Fields({
    "model": config_mapping(DiffusionPolicyConfig, {
        **{key: Whole(1) for key in ("max_nodes", "max_neighbors", "d_model", "heads", "encoder_layers", "denoiser_layers",
                                     "horizon", "obs_steps", "action_steps", "num_train_timesteps", "num_inference_steps")},
        "prediction_type": Text(PREDICTION_TYPES),
        "sampler": Text(SAMPLERS),
    }),
    "train": Fields({
        "max_epochs": Whole(1), "batch_size": Whole(1), "lr": positive(), "weight_decay": Real(0.0),
        "warmup_steps": Whole(0), "ema_decay": fraction(), "val_fraction": Real(0.0, 1.0, high_open=True),
        "augment": Flag(), "seed": Whole(0), "max_minutes": Maybe(positive("minutes"), "no cap"),
        "val_accuracy_samples": Whole(0),
    }, frozenset({"val_accuracy_samples"})),  # not in params.yaml: PlannerTrainConfig's default
    "accelerator": Text(note="Lightning's accelerator: cpu, gpu, auto"),
    "devices": DEVICES,
    "threads": Maybe(Whole(0, note="0: torch's default"), "torch's default"),
    "experiment": Text(note="an MLflow experiment"),
})
KEYS = keys_of(SETTINGS)


def main(params_path: str = "params.yaml", variant: str = "guide", accelerator: str | None = None,
         devices: str | None = None, afresh: bool = False, max_epochs: int | None = None) -> dict:
    if variant not in VARIANTS:
        raise SystemExit(f"error: unknown planner variant {variant!r}; choose from {', '.join(VARIANTS)}")
    check_stage(params_path, "train_planner", SETTINGS, protocol=False)
    params = load_params(params_path)
    section = complete_section(params, "train_planner", params_path, KEYS)
    metrics = train_and_report(section, variant, accelerator, devices, afresh, max_epochs)
    if metrics:
        print(f"{variant} planner: {metrics['num_parameters']:,} parameters, {metrics['epochs']} epochs in "
              f"{metrics['train_seconds']} s; val loss {metrics['val_loss']}, first-step accuracy {metrics['val_first_step_accuracy']} -> {POLICIES[variant].model}")
    return metrics


if __name__ == "__main__":
    parser = stage_arguments(__doc__)
    parser.add_argument("--variant", default="guide", choices=VARIANTS, help="guide (global graph with predictions) or dare (observed graph only)")
    parser.add_argument("--accelerator", help="Lightning accelerator (cpu, gpu, auto) [params]")
    parser.add_argument("--devices", help="Lightning devices (1, 2, auto) [params]")
    parser.add_argument("--afresh", action="store_true",
                        help="train from the start even if checkpoints/planner_<variant> holds a run of the same settings and data")
    parser.add_argument("--max-epochs", type=int, help="override train_planner.train.max_epochs")
    a = parser.parse_args()
    run_stage_main(main, a.params, a.variant, a.accelerator, a.devices, a.afresh, a.max_epochs)
