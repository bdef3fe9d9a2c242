"""Stage II training and its report (the `train_planner` stage): the diffusion policy of one
variant trained on its observations, then its metrics and training curves."""

from __future__ import annotations

import json
from pathlib import Path

from pipeline.common.paths import POLICIES
from pipeline.models.modeling_diffusion import load_policy
from pipeline.training.policy import train_planner


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


def train_and_report(section: dict, variant: str, accelerator: str | None = None, devices: str | None = None,
                     resume: bool = False, max_epochs: int | None = None) -> dict:
    """Train the `variant` policy from the `train_planner` settings and write its metrics and curves;
    the metrics ({} in a process of a multi-device run other than the first)."""
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
    return metrics
