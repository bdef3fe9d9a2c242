"""Coverage curves of a benchmark, of one robot or of teams: the mean explored share over maps with a
band of one standard deviation, per planner against distance and time (`coverage_figure`,
`exploration_curves.mean_curve`), or per team run against the team's time (`team_coverage_figure`)."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping

import numpy as np
import pandas as pd

from pipeline.common.atomic import atomic_file
from pipeline.evaluation.exploration_curves import SpeedModel, StepRecord, mean_curve, share_at

GRID_POINTS = 400  # samples along each axis


def _pyplot() -> Any:
    """matplotlib's pyplot on its file backend (imported here: a heavy dependency)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _curve(ax: Any, grid: np.ndarray, mean: np.ndarray, std: np.ndarray, alpha: float, **line: Any) -> None:
    """One mean curve in percent with its band of one standard deviation (clipped to 0-100 %)."""
    ax.plot(grid, 100 * mean, lw=1.4, **line)
    band = 100 * np.clip(mean - std, 0, 1), 100 * np.clip(mean + std, 0, 1)
    ax.fill_between(grid, *band, color=line["color"], alpha=alpha, lw=0)


def _save(fig: Any, plt: Any, path: str | Path) -> Path:
    fig.tight_layout()
    path = Path(path)
    with atomic_file(path) as tmp:
        fig.savefig(tmp)
    plt.close(fig)
    return path


def coverage_figure(
    records: Mapping[tuple[str, str], StepRecord], path: str | Path, speed: SpeedModel = SpeedModel(), title: str = ""
) -> Path:
    """Two panels (explored share against distance, and against time at `speed`), one line per
    planner, legend ordered by the share at the middle of the distance axis; a PNG at `path`."""
    plt = _pyplot()
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
            label = f"{planner} ({maps})" if ax is axes[0] else None
            _curve(ax, grid, mean, std, band_alpha, color=color, ls=style, label=label)
    axes[0].set_xlabel("distance travelled (m)")
    axes[1].set_xlabel(f"time (s) at {speed.speed_mps:g} m/s, waiting while deciding")
    axes[0].set_ylabel("explored share of the free area (%)")
    for ax in axes:
        ax.set_ylim(0, 101)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, loc="lower right", title="planner (maps)", title_fontsize=7)
    fig.suptitle(title or "Coverage curves: mean over maps, band one standard deviation", fontsize=10)
    return _save(fig, plt, path)


def team_coverage_figure(coverage: pd.DataFrame, path: str | Path, title: str = "") -> Path:
    """Team coverage against time: per run (`label` column) the mean explored share over maps
    against the team's time in metres of travel, with a band of one standard deviation; one
    colour per planner spec, one dash per robot count. `coverage` has team_coverage.csv's
    columns (label, map, robots, time_m, explored_share). A PNG at `path`."""
    plt = _pyplot()
    if coverage.empty:
        raise ValueError("no team coverage to draw")
    grid = np.linspace(0.0, max(float(coverage["time_m"].max()), 1e-9), GRID_POINTS)
    runs = list(dict.fromkeys(coverage["label"]))  # in the table's (task) order
    specs = list(dict.fromkeys(run.rsplit("@", 1)[0] for run in runs))
    counts = sorted(set(int(c) for c in coverage["robots"]))
    colors = plt.get_cmap("tab10")
    styles = ("-", "--", "-.", ":")
    fig, ax = plt.subplots(figsize=(7.5, 4.4), dpi=120)
    for run in runs:
        rows = coverage[coverage["label"] == run]
        shares = np.stack(
            [
                share_at({"explored_share": episode["explored_share"].to_numpy()}, grid, episode["time_m"].to_numpy())
                for _, episode in rows.groupby("map", sort=True)
            ]
        )
        color = colors(specs.index(run.rsplit("@", 1)[0]) % colors.N)
        style = styles[counts.index(int(rows["robots"].iloc[0])) % len(styles)]
        _curve(
            ax,
            grid,
            shares.mean(axis=0),
            shares.std(axis=0),
            0.1,
            color=color,
            ls=style,
            label=f"{run} ({len(shares)})",
        )
    ax.set_xlabel("team time (metres each robot can travel)")
    ax.set_ylabel("explored share of the free area (%)")
    ax.set_ylim(0, 101)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, loc="lower right", title="run (maps)", title_fontsize=7)
    ax.set_title(title or "Team coverage: mean over maps, band one standard deviation", fontsize=10)
    return _save(fig, plt, path)
