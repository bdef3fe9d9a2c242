"""Coverage curves: per planner, the mean explored share against distance and against time, with a
band of one standard deviation over maps (`exploration_curves.mean_curve`)."""

from __future__ import annotations

from pathlib import Path
from typing import Mapping

import numpy as np

from pipeline.common.atomic import atomic_file
from pipeline.evaluation.exploration_curves import SpeedModel, StepRecord, mean_curve

GRID_POINTS = 400  # samples along each axis


def coverage_figure(
    records: Mapping[tuple[str, str], StepRecord], path: str | Path, speed: SpeedModel = SpeedModel(), title: str = ""
) -> Path:
    """Two panels (explored share against distance, and against time at `speed`), one line per
    planner, legend ordered by the share at the middle of the distance axis; a PNG at `path`."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not records:
        raise ValueError("no per-step records to draw")
    by_planner: dict[str, list[StepRecord]] = {}
    for (planner, _), record in sorted(records.items()):
        by_planner.setdefault(planner, []).append(record)
    max_distance = max(float(r["distance_m"][-1]) for r in records.values())
    max_time = max(float(speed.times(r)[-1]) for r in records.values())
    distance_grid = np.linspace(0.0, max(max_distance, 1e-9), GRID_POINTS)
    time_grid = np.linspace(0.0, max(max_time, 1e-9), GRID_POINTS)
    curves = {
        planner: (mean_curve(group, distance_grid), mean_curve(group, time_grid, speed))
        for planner, group in by_planner.items()
    }
    middle = GRID_POINTS // 2
    order = sorted(curves, key=lambda planner: -curves[planner][0][0][middle])
    colors = plt.get_cmap("tab10")
    styles = ("-", "--", "-.")  # past ten planners the colours repeat with another dash
    band_alpha = 0.14 if len(order) <= 4 else 0.05  # many overlapping bands would hide the lines

    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2), dpi=120, sharey=True)
    for k, planner in enumerate(order):
        color, style = colors(k % colors.N), styles[(k // colors.N) % len(styles)]
        maps = len(by_planner[planner])
        for ax, grid, (mean, std) in (
            (axes[0], distance_grid, curves[planner][0]),
            (axes[1], time_grid, curves[planner][1]),
        ):
            ax.plot(
                grid, 100 * mean, color=color, ls=style, lw=1.4, label=f"{planner} ({maps})" if ax is axes[0] else None
            )
            ax.fill_between(
                grid,
                100 * np.clip(mean - std, 0, 1),
                100 * np.clip(mean + std, 0, 1),
                color=color,
                alpha=band_alpha,
                lw=0,
            )
    axes[0].set_xlabel("distance travelled (m)")
    axes[1].set_xlabel(f"time (s) at {speed.speed_mps:g} m/s, waiting while deciding")
    axes[0].set_ylabel("explored share of the free area (%)")
    for ax in axes:
        ax.set_ylim(0, 101)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="lower right", title="planner (maps)", title_fontsize=7)
    fig.suptitle(title or "Coverage curves: mean over maps, band one standard deviation", fontsize=10)
    fig.tight_layout()
    path = Path(path)
    with atomic_file(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
    return path
