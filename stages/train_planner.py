"""DVC stage: Stage II training of the diffusion planner (one run per variant: guide, dare).

Reads only the `train_planner` section of params.yaml. Trains on the variant's observations and
writes its model folder (policy.pt, the EMA weights for inference; last.ckpt and best.ckpt for
resuming), metrics and curves: the paths of `policies` in pipeline/paths.yaml.
"""

from __future__ import annotations

import json
from pathlib import Path

from pipeline.common.params import complete_section, load_params
from pipeline.common.paths import POLICIES
from pipeline.models.modeling_diffusion import load_policy
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.training.policy import train_planner

VARIANTS = tuple(POLICIES)  # guide, dare
KEYS = ("model", "train", "accelerator", "devices", "threads", "experiment")


def plot_curves(history: list[dict], path: Path, title: str) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    epochs = [h["epoch"] + 1 for h in history]
    fig, (ax_loss, ax_acc) = plt.subplots(1, 2, figsize=(10, 3.6))
    ax_loss.plot(epochs, [h["train_loss"] for h in history], label="train")
    ax_loss.plot(epochs, [h["val_loss"] for h in history], label="val (EMA)")
    ax_loss.set_xlabel("epoch")
    ax_loss.set_ylabel("DDPM loss (MSE)")
    ax_loss.set_yscale("log")
    ax_loss.legend()
    ax_loss.grid(alpha=0.3)
    ax_acc.plot(epochs, [h["val_first_step_accuracy"] for h in history], color="#c44e52")
    ax_acc.set_xlabel("epoch")
    ax_acc.set_ylabel("first sampled step = expert's (val)")
    ax_acc.set_ylim(0, 1)
    ax_acc.grid(alpha=0.3)
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main(params_path: str = "params.yaml", variant: str = "guide", accelerator: str | None = None,
         devices: str | None = None, resume: bool = False, max_epochs: int | None = None) -> dict:
    if variant not in VARIANTS:
        raise SystemExit(f"error: unknown planner variant {variant!r}; choose from {', '.join(VARIANTS)}")
    params = load_params(params_path)
    section = complete_section(params, "train_planner", params_path, KEYS)
    paths = POLICIES[variant]
    train = dict(section["train"] or {})
    if max_epochs is not None:
        train["max_epochs"] = int(max_epochs)
    export = train_planner(
        paths.observations,
        paths.model,
        dict(section["model"] or {}),
        train,
        accelerator=accelerator or section["accelerator"],
        devices=devices or section["devices"],
        resume=resume,
        experiment_name=str(section["experiment"]),
        run_name=variant,
        num_threads=section["threads"],
    )
    if export is None:  # another process of a multi-device run: rank zero exports and reports
        return {}
    policy, meta = load_policy(export)
    history = meta.get("history", [])
    last = history[-1] if history else {}
    metrics = {
        "variant": variant,
        "num_parameters": policy.num_parameters(),
        "epochs": meta.get("epochs"),
        "train_seconds": meta.get("train_seconds"),
        "samples": meta.get("samples"),
        "val_loss": last.get("val_loss"),
        "val_first_step_accuracy": last.get("val_first_step_accuracy"),
        "trained_on": meta.get("trained_on"),  # torch build, CPU kernels, threads: weights differ across hosts
    }
    paths.metrics.parent.mkdir(parents=True, exist_ok=True)
    paths.metrics.write_text(json.dumps(metrics, indent=2) + "\n")
    if history:
        plot_curves(history, paths.curves, f"{variant} diffusion planner")
    print(f"{variant} planner: {metrics['num_parameters']:,} parameters, {metrics['epochs']} epochs in "
          f"{metrics['train_seconds']} s; val loss {metrics['val_loss']}, first-step accuracy {metrics['val_first_step_accuracy']} -> {export}")
    return metrics


if __name__ == "__main__":
    parser = stage_arguments(__doc__)
    parser.add_argument("--variant", default="guide", choices=VARIANTS, help="guide (global graph with predictions) or dare (observed graph only)")
    parser.add_argument("--accelerator", help="Lightning accelerator (cpu, gpu, auto) [params]")
    parser.add_argument("--devices", help="Lightning devices (1, 2, auto) [params]")
    parser.add_argument("--resume", action="store_true", help="continue from models/planner_<variant>/last.ckpt")
    parser.add_argument("--max-epochs", type=int, help="override train_planner.train.max_epochs")
    a = parser.parse_args()
    run_stage_main(main, a.params, a.variant, a.accelerator, a.devices, a.resume, a.max_epochs)
