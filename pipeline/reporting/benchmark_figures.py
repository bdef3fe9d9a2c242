"""Figures of the `benchmark` stage on the test mazes: the bar chart of each planner's mean distance
and completion, and the first maze with every planner's path side by side."""

from __future__ import annotations

from pathlib import Path

from pipeline.common.atomic import atomic_file
from pipeline.reporting.panels import render_comparison
from pipeline.reporting.render import save_png
from pipeline.world.trajectories import read_trajectory_csv


def distance_bar_chart(summary, path: Path) -> None:
    """Bar chart of mean distance (+- std) and completion per planner, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.2), dpi=120)
    names = list(summary.index)
    ax.barh(names, summary["distance_mean_m"], xerr=summary["distance_std_m"], color="#4c72b0", capsize=3)
    for y, (_, row) in enumerate(summary.iterrows()):
        ax.text(
            row.distance_mean_m + row.distance_std_m + 5,
            y,
            f"{row.distance_mean_m:.0f} m, {row.completion_rate * 100:.0f} % done",
            va="center",
            fontsize=8,
        )
    ax.invert_yaxis()
    ax.set_xlabel("distance to complete exploration (m), mean +- std over test mazes")
    ax.set_xlim(0, float((summary["distance_mean_m"] + summary["distance_std_m"]).max()) * 1.35)
    fig.tight_layout()
    with atomic_file(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)


def planner_paths_figure(ground_truth, frame, out_dir: Path, path: Path) -> None:
    """One map with every planner's path side by side."""
    rows = frame[frame["map"] == ground_truth.name]
    panels = [
        (row.planner, read_trajectory_csv(out_dir / row.planner / f"{ground_truth.name}.csv"), float(row.distance_m))
        for row in rows.itertuples()
    ]
    save_png(render_comparison(ground_truth, panels), path)
