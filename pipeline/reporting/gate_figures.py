"""The sliver gate's figure (the `fit_gate` stage): ROC curves on the held-out training maps."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.common.atomic import atomic_file


def gate_roc_curves(curves: dict[str, tuple[np.ndarray, np.ndarray, float]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(5, 4.5))
    for name, (fpr, tpr, auc) in curves.items():
        ax.plot(fpr, tpr, label=f"{name} (AUC {auc:.3f})", lw=2 if name.startswith("gate") else 1)
    ax.plot([0, 1], [0, 1], color="0.7", lw=0.8, ls="--")
    ax.set(
        xlabel="slivers passed (false positive rate)",
        ylabel="big targets passed (true positive rate)",
        title="Sliver gate on held-out training maps",
    )
    ax.legend(loc="lower right", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:
        fig.savefig(tmp, dpi=120)
    plt.close(fig)
