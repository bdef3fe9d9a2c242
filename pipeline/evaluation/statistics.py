"""The statistics of a benchmark: per-planner summaries and paired differences between planners.

Distances vary between maps far more than between planners (about 65 m on 100 m mazes), so a
comparison pairs the planners map by map and reports Student's t interval of the mean
difference; a planner's gap to the `optimal` reference is the paper's measure.
"""

from __future__ import annotations

import math

import pandas as pd
import scipy.stats

REFERENCE_PLANNER = "optimal"


def student_t_975(dof: int) -> float:
    """The two-sided 95 % quantile of Student's t: 1.96 would be 11 % too narrow on 12 maps."""
    return float(scipy.stats.t.ppf(0.975, dof))


def paired_difference(frame: pd.DataFrame, planner: str, baseline: str) -> tuple[float, float, int]:
    """(mean, 95 % half-width, maps) of planner minus baseline distance over the maps both ran,
    as fractions of the baseline's mean there; the half-width is Student's t interval. NaNs when they share no map (half-width: < 2 maps).

    Per-maze spread (about 65 m on 100 m mazes) swamps most differences between planners on a
    handful of mazes; pairing by map removes the mazes' own difficulty, and the interval says
    which differences the test set can resolve.
    """
    by_map = frame.groupby(["planner", "map"])["distance_m"].mean()
    if planner not in by_map.index.get_level_values(0) or baseline not in by_map.index.get_level_values(0):
        return float("nan"), float("nan"), 0
    ours, theirs = by_map.loc[planner], by_map.loc[baseline]
    maps = ours.index.intersection(theirs.index)
    base = float(theirs.loc[maps].mean()) if len(maps) else float("nan")
    if not len(maps) or not base > 0:
        return float("nan"), float("nan"), 0
    diff = (ours.loc[maps] - theirs.loc[maps]).astype(float).to_numpy()
    half = (
        student_t_975(len(diff) - 1) * diff.std(ddof=1) / math.sqrt(len(diff)) / base if len(diff) > 1 else float("nan")
    )
    return float(diff.mean() / base), float(half), int(len(diff))


def summarise(frame: pd.DataFrame) -> pd.DataFrame:
    """Per planner: mean and std distance, completion rate, decision time."""
    groups = frame.groupby("planner", sort=True)
    summary = pd.DataFrame(
        {
            "episodes": groups.size(),
            "completion_rate": groups["complete"].mean(),
            "distance_mean_m": groups["distance_m"].mean(),
            "distance_std_m": groups["distance_m"].std(ddof=0),
            "decision_ms_median": groups["decision_ms_median"].median(),
            "decision_ms_p95": groups["decision_ms_p95"].median(),
        }
    )
    if REFERENCE_PLANNER in summary.index:
        # The paper's gap: mean distance over the reference's mean distance, minus one.
        summary["gap_to_optimal"] = summary["distance_mean_m"] / summary.loc[REFERENCE_PLANNER, "distance_mean_m"] - 1.0
    return summary.sort_values("distance_mean_m")
