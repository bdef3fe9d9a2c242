"""Figures of the training stages: the inpainter's curves and sample predictions (`train_inpainter`),
the diffusion planner's curves (`train_planner`), the block model's curve and one example
(`train_block_model`), the drl policy's curves (`train_drl`) and the DAgger rounds (`distil_policy`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np

from pipeline.common.atomic import atomic_file


def inpainter_training_curves(history: list[dict[str, float]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    epochs = [h["epoch"] + 1 for h in history]
    fig, (ax_loss, ax_val) = plt.subplots(1, 2, figsize=(10, 3.8))
    ax_loss.plot(epochs, [h["train_loss"] for h in history], label="train loss")
    ax_loss.plot(epochs, [h["val_loss"] for h in history], label="val loss")
    ax_loss.set_xlabel("epoch")
    ax_loss.set_ylabel("BCE (hole + weighted known)")
    ax_loss.legend()
    ax_loss.grid(alpha=0.3)
    for key, label in (("val_f1", "F1"), ("val_precision", "precision"), ("val_recall", "recall")):
        ax_val.plot(epochs, [h[key] for h in history], label=label, linewidth=2 if key == "val_f1" else 1)
    ax_val.set_xlabel("epoch")
    ax_val.set_ylabel("free nodes in unknown space (val)")
    ax_val.set_ylim(0, 1)
    ax_val.legend()
    ax_val.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def _node_rgb(image: np.ndarray, valid: np.ndarray) -> np.ndarray:
    rgb = np.zeros(image.shape + (3,), dtype=np.float32)
    rgb[image >= 192] = (1.0, 1.0, 1.0)
    rgb[(image > 63) & (image < 192)] = (0.55, 0.7, 0.9)  # unknown
    rgb[~valid] = (0.35, 0.35, 0.35)  # padding
    return rgb


def inpainter_sample_predictions(model, val_pairs: dict, threshold: float, path: Path, count: int = 6) -> None:
    """Rows of observed / predicted probability / hits at tau / ground truth for validation pairs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    samples = [(size, i) for size, group in sorted(val_pairs.items()) for i in range(len(group["observed"]))]
    picks = [samples[k] for k in np.linspace(0, len(samples) - 1, min(count, len(samples))).astype(int)]
    fig, axes = plt.subplots(len(picks), 4, figsize=(10, 2.6 * len(picks)), squeeze=False)
    cmap = plt.get_cmap("magma")
    for row, (size, i) in enumerate(picks):
        observed = val_pairs[size]["observed"][i]
        target = val_pairs[size]["target"][i]
        valid = val_pairs[size]["valid"][i]
        prob = model.predict(observed)
        hole = (observed > 63) & (observed < 192) & valid
        predicted = _node_rgb(observed, valid)
        predicted[hole] = cmap(prob[hole])[:, :3]
        hits = _node_rgb(observed, valid)
        hits[hole] = (0.1, 0.1, 0.1)
        free = target >= 192
        pred = (prob >= threshold) & hole
        hits[pred & free] = (0.1, 0.8, 0.2)  # true positive
        hits[pred & ~free] = (0.9, 0.1, 0.1)  # false positive
        hits[~pred & free & hole] = (1.0, 0.65, 0.0)  # missed
        truth = _node_rgb(np.where(free, 255, 0).astype(np.uint8), valid)
        tp, fp = int((pred & free).sum()), int((pred & ~free).sum())
        titles = (
            "observed",
            "predicted P(free) in unknown",
            f"at tau={threshold}: {tp} hit / {fp} false",
            "ground truth",
        )
        for col, (image, title) in enumerate(zip((_node_rgb(observed, valid), predicted, hits, truth), titles)):
            ax = axes[row, col]
            ax.imshow(image, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0 or col == 2:
                ax.set_title(title, fontsize=8)
    fig.suptitle(
        "validation pairs: white free, black obstacle, blue unknown, grey padding; green hit, red false, orange missed",
        fontsize=8,
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)


def planner_training_curves(history: list[dict], path: Path, title: str) -> None:
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
    with atomic_file(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def block_model_training_figure(
    history: list[dict[str, float]], example: tuple[np.ndarray, np.ndarray, np.ndarray] | None, path: Path
) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 4, figsize=(14, 3.4))
    epochs = [row["epoch"] for row in history]
    axes[0].plot(epochs, [row["loss"] for row in history], "o-", label="training loss")
    axes[0].plot(epochs, [row["held_out_error"] for row in history], "s-", label="held-out block error")
    axes[0].set(xlabel="epoch", title="Block model")
    axes[0].legend(fontsize=8)
    if example is not None:
        shares, probability, truth = example
        seen = np.where(shares[2] > 0.5, 0.5, shares[0] > 0.5)
        for ax, image, title in zip(
            axes[1:], (seen, probability, truth), ("seen (grey: unknown)", "P(free)", "true blocks")
        ):
            ax.imshow(image, cmap="gray", vmin=0, vmax=1)
            ax.set(title=title, xticks=[], yticks=[])
    else:
        for ax in axes[1:]:
            ax.axis("off")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def drl_training_curves(rows: list[dict[str, float]], evaluation: dict[str, Any], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(13, 3.4))
    rows = [r for r in rows if "episode_return" in r]
    steps = [r["timesteps"] for r in rows]
    for ax, key, title in zip(
        axes,
        ("episode_return", "episode_distance_m", "explored_share"),
        ("episode return", "episode distance (m)", "explored share at episode end"),
    ):
        ax.plot(steps, [r[key] for r in rows], ".-", lw=1)
        ax.set(xlabel="environment steps", title=title)
    if evaluation:
        axes[1].axhline(
            evaluation["nearest_frontier_distance_m"],
            color="grey",
            ls="--",
            label=f"nearest_frontier on {evaluation['mazes']} fresh {evaluation['side_m']:g} m mazes",
        )
        axes[1].axhline(evaluation["distance_m"], color="tab:red", ls=":", label="drl (greedy) on the same mazes")
        axes[1].legend(fontsize=7)
    fig.suptitle("drl: MaskablePPO in guide/Explore-v0 (means over each rollout's finished episodes)", fontsize=9)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:  # a kill mid-write leaves the previous figure, as for every other figure
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def dagger_rounds_figure(rows: list[dict], path: Path) -> None:
    """Agreement with the teacher and the closed-loop distance against greedy_utility, per round."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    labels = [str(r["round"]) for r in rows]
    fig, (ax_agree, ax_dist) = plt.subplots(1, 2, figsize=(10, 3.6))
    rounds = [r for r in rows if r["round"] != "start"]
    ax_agree.plot(
        [str(r["round"]) for r in rounds], [r["heldout_agreement"] for r in rounds], "o-", label="held-out states"
    )
    ax_agree.plot(
        [str(r["round"]) for r in rounds],
        [r["driver_agreement"] for r in rounds],
        "s--",
        label="the driver's moves (round r: round r - 1's policy; 0: the teacher)",
    )
    ax_agree.set(xlabel="round", ylabel="first step = teacher's", ylim=(0, 1))
    ax_agree.legend(fontsize=8)
    ax_agree.grid(alpha=0.3)
    values = [r["vs_greedy_pct"] for r in rows]
    errors = [r["vs_greedy_ci95_pct"] or 0.0 for r in rows]
    ax_dist.errorbar(labels, values, yerr=errors, fmt="o-", capsize=3, color="#c44e52")
    ax_dist.axhline(0.0, color="grey", ls="--", lw=1)
    ax_dist.set(xlabel="round (start: the expert-trained policy)", ylabel="guide:mode=policy vs greedy_utility (%)")
    ax_dist.grid(alpha=0.3)
    fig.suptitle(
        f"DAgger: the policy driving, labelled by the teacher ({rows[-1].get('mazes')} fresh mazes, paired, 95 %)",
        fontsize=9,
    )
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)
