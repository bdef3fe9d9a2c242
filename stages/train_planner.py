"""DVC stage: Stage II training of the diffusion planner (one run per variant: guide, dare).

Reads only the `train_planner` section of params.yaml. Trains on the variant's observations and
writes its model folder (policy.pt, the EMA weights for inference; Lightning's last.ckpt and
best.ckpt go to checkpoints/planner_<variant>/, where a killed run resumes from when its settings
and observations are the same), metrics and curves: the paths of `policies` in pipeline/paths.yaml.
"""

from __future__ import annotations

from pipeline.common.paths import POLICIES
from pipeline.stage_runner import read_stage, run_stage_main, stage_arguments
from pipeline.workflows.train_planner import Settings, train_and_report

VARIANTS = tuple(POLICIES)  # guide, dare


def main(
    params_path: str = "params.yaml",
    variant: str = "guide",
    accelerator: str | None = None,
    devices: str | None = None,
    afresh: bool = False,
    max_epochs: int | None = None,
) -> dict:
    if variant not in VARIANTS:
        raise SystemExit(f"error: unknown planner variant {variant!r}; choose from {', '.join(VARIANTS)}")
    settings = read_stage(params_path, "train_planner", Settings)
    metrics = train_and_report(settings, variant, accelerator, devices, afresh, max_epochs)
    if metrics:
        print(
            f"{variant} planner: {metrics['num_parameters']:,} parameters, {metrics['epochs']} epochs in "
            f"{metrics['train_seconds']} s; val loss {metrics['val_loss']}, first-step accuracy {metrics['val_first_step_accuracy']} -> {POLICIES[variant].model}"
        )
    return metrics


if __name__ == "__main__":
    parser = stage_arguments(__doc__)
    parser.add_argument(
        "--variant",
        default="guide",
        choices=VARIANTS,
        help="guide (global graph with predictions) or dare (observed graph only)",
    )
    parser.add_argument("--accelerator", help="Lightning accelerator (cpu, gpu, auto) [params]")
    parser.add_argument("--devices", help="Lightning devices (1, 2, auto) [params]")
    parser.add_argument(
        "--afresh",
        action="store_true",
        help="train from the start even if checkpoints/planner_<variant> holds a run of the same settings and data",
    )
    parser.add_argument("--max-epochs", type=int, help="override train_planner.train.max_epochs")
    a = parser.parse_args()
    run_stage_main(main, a.params, a.variant, a.accelerator, a.devices, a.afresh, a.max_epochs)
