"""The paper's result tables (I-V) computed from our benchmark outputs, beside the paper's numbers.

Every table function is pure: it takes a pandas frame of metrics.csv rows (columns map,
planner, distance_m, steps, complete, explored_ratio, decision_ms_median, decision_ms_p95,
seed and, from `run_benchmark`, failure) and returns a frame with one row per planner
(a `planner` column, never an index) so that it can be written as markdown
(`pipeline.reporting.table_markdown`), DVC metrics and MLflow runs
(`pipeline.reporting.mlflow_tables`) alike.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import pandas as pd

from pipeline.evaluation.benchmark import DEFAULT_BASELINE as PAIRED_BASELINE
from pipeline.evaluation.statistics import paired_difference
from pipeline.reporting.paper_numbers import PAPER_TABLE4, paper_row, paper_table2_or_3

NOT_RUN = "not run"
REFERENCE_PLANNER = "optimal"
ABLATION_PLANNERS = ("guide", "guide_noregion", "guide_tsp", "dare")
K_PLANNERS = ("guide", "dare")
TABLE5_COLUMNS = (
    "planner",
    "maps",
    "explored_m2",
    "distance_m",
    "time_s",
    "efficiency_m2_per_m",
    "efficiency_m2_per_s",
    "distance_to_90_m",
    "distance_to_99_m",
    "coverage_auc",
    "reached_90",
    "reached_99",
)
REQUIRED_COLUMNS = ("map", "planner", "distance_m", "complete", "decision_ms_median", "decision_ms_p95")


def finite_number(value: Any) -> float | None:
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        return int(value)
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return round(number, 6) if math.isfinite(number) else None


def check_metrics(frame: pd.DataFrame, what: str = "metrics") -> pd.DataFrame:
    """The frame with `complete` as bool; ValueError naming the missing columns."""
    missing = [c for c in REQUIRED_COLUMNS if c not in frame.columns]
    if missing:
        raise ValueError(
            f"{what}: missing column(s) {missing}; expected metrics.csv rows ({', '.join(REQUIRED_COLUMNS)}, ...)"
        )
    frame = frame.copy()
    complete = frame["complete"]
    if complete.dtype == object:
        complete = complete.astype(str).str.strip().str.lower().isin(("true", "1", "yes"))
    frame["complete"] = complete.astype(bool)
    return frame


def read_metrics(path: str | Path) -> pd.DataFrame:
    """metrics.csv as a frame (checked)."""
    return check_metrics(pd.read_csv(path), str(path))


def read_precision(path: str | Path) -> pd.DataFrame | None:
    """The eval_predictor stage's precision.csv, or None when it does not exist."""
    path = Path(path)
    return pd.read_csv(path) if path.is_file() else None


def _planner_stats(rows: pd.DataFrame) -> dict[str, float]:
    distance = rows["distance_m"].astype(float)
    return {
        "episodes": int(len(rows)),
        "distance_mean_m": float(distance.mean()),
        "distance_std_m": float(distance.std(ddof=0)),
        "completion_rate": float(rows["complete"].mean()),
        "decision_ms_median": float(rows["decision_ms_median"].median()),
        "decision_ms_p95": float(rows["decision_ms_p95"].median()),
    }


def _optimal_mean(frame: pd.DataFrame) -> float:
    rows = frame[frame["planner"] == REFERENCE_PLANNER]
    return float(rows["distance_m"].mean()) if len(rows) else float("nan")


def _gap(mean: float, optimal: float) -> float:
    return mean / optimal - 1.0 if np.isfinite(optimal) and optimal > 0 and np.isfinite(mean) else float("nan")


# --------------------------------------------------------------------------- Table II
TABLE2_COLUMNS = [
    "planner",
    "paper_row",
    "episodes",
    "distance_mean_m",
    "distance_std_m",
    "completion_rate",
    "gap_to_optimal",
    "vs_baseline",
    "vs_baseline_ci95",
    "decision_ms_median",
    "decision_ms_p95",
    "paper_distance_m",
    "paper_gap_pct",
    "paper_source",
]


def table2(frame: pd.DataFrame) -> pd.DataFrame:
    """Per planner: mean/std distance, completion, gap to `optimal` (mean / optimal mean - 1,
    NaN when optimal was not run), the paired difference to `greedy_utility` with its 95 %
    half-width (`paired_difference`), decision ms, and the paper's distance and gap (%):
    Table II, or Table III for the ablations (guide_noregion, guide_tsp); sorted by distance."""
    frame = check_metrics(frame)
    optimal = _optimal_mean(frame)
    rows = []
    for planner, group in frame.groupby("planner", sort=True):
        stats = _planner_stats(group)
        paired = paired_difference(frame, str(planner), PAIRED_BASELINE)
        paper_distance, paper_gap, source = paper_table2_or_3(str(planner), prefer="Table II")
        rows.append(
            {
                "planner": str(planner),
                "paper_row": paper_row(planner),
                **stats,
                "gap_to_optimal": _gap(stats["distance_mean_m"], optimal),
                "vs_baseline": paired[0],
                "vs_baseline_ci95": paired[1],
                "paper_distance_m": paper_distance,
                "paper_gap_pct": paper_gap,
                "paper_source": source,
            }
        )
    table = pd.DataFrame(rows, columns=TABLE2_COLUMNS)
    return table.sort_values(["distance_mean_m", "planner"], kind="stable").reset_index(drop=True)


# --------------------------------------------------------------------------- Table III
TABLE3_COLUMNS = [
    "planner",
    "paper_row",
    "status",
    "episodes",
    "distance_mean_m",
    "distance_std_m",
    "completion_rate",
    "gap_to_optimal",
    "decision_ms_median",
    "paper_distance_m",
    "paper_gap_pct",
    "paper_source",
]


def table3(frame: pd.DataFrame, planners: Sequence[str] = ABLATION_PLANNERS) -> pd.DataFrame:
    """The ablation rows in the order given: our numbers (status "not run" and NaNs for a
    planner absent from the metrics) beside the paper's (Table III, else Table II for DARE)."""
    frame = check_metrics(frame)
    optimal = _optimal_mean(frame)
    rows = []
    for planner in planners:
        group = frame[frame["planner"] == planner]
        paper_distance, paper_gap, source = paper_table2_or_3(planner)
        row: dict[str, Any] = {
            "planner": planner,
            "paper_row": paper_row(planner),
            "status": "ok" if len(group) else NOT_RUN,
            "paper_distance_m": paper_distance,
            "paper_gap_pct": paper_gap,
            "paper_source": source,
        }
        if len(group):
            stats = _planner_stats(group)
            stats.pop("decision_ms_p95")
            row.update(stats, gap_to_optimal=_gap(stats["distance_mean_m"], optimal))
        else:
            row.update(episodes=0)
        rows.append(row)
    return pd.DataFrame(rows, columns=TABLE3_COLUMNS)


# --------------------------------------------------------------------------- Table IV
TABLE4_COLUMNS = [
    "planner",
    "K",
    "label",
    "status",
    "episodes",
    "decision_ms_median",
    "decision_ms_p95",
    "distance_mean_m",
    "completion_rate",
    "paper_decision_s",
    "paper_distance_m",
]


def sweep_label(planner: str, k: int) -> str:
    """The label of one point of the denoising-steps sweep, e.g. guide_k10."""
    return f"{planner}_k{int(k)}"


def table4(sweep: pd.DataFrame, k_values: Sequence[int], planners: Sequence[str] = K_PLANNERS) -> pd.DataFrame:
    """Per (planner, K) of a sweep labelled f"{planner}_k{K}": decision time (median over
    episodes of the per-episode median / p95, ms), pooled mean distance and completion, and
    the paper's decision time (s) and distance (m, Gazebo scenes). Absent points: "not run"."""
    sweep = check_metrics(sweep, "sweep metrics")
    rows = []
    for planner in planners:
        for k in k_values:
            label = sweep_label(planner, k)
            group = sweep[sweep["planner"] == label]
            paper_s, paper_m = PAPER_TABLE4.get(paper_row(planner), {}).get(int(k), (np.nan, np.nan))
            row: dict[str, Any] = {
                "planner": planner,
                "K": int(k),
                "label": label,
                "status": "ok" if len(group) else NOT_RUN,
                "episodes": int(len(group)),
                "paper_decision_s": paper_s,
                "paper_distance_m": paper_m,
            }
            if len(group):
                stats = _planner_stats(group)
                row.update(
                    {
                        key: stats[key]
                        for key in ("decision_ms_median", "decision_ms_p95", "distance_mean_m", "completion_rate")
                    }
                )
            rows.append(row)
    return pd.DataFrame(rows, columns=TABLE4_COLUMNS)


# --------------------------------------------------------------------------- Table V
def table5(exploration: pd.DataFrame) -> pd.DataFrame:
    """Table V on our maps from a benchmark's exploration.csv (`exploration_curves.planner_table`):
    per planner the explored area, distance, time, and the two efficiencies, best per metre first."""
    missing = [c for c in TABLE5_COLUMNS if c not in exploration.columns]
    if missing:
        raise ValueError(f"exploration table lacks {', '.join(missing)}; rerun the benchmark stage")
    table = exploration.loc[:, list(TABLE5_COLUMNS)].sort_values("efficiency_m2_per_m", ascending=False)
    return table.reset_index(drop=True)
