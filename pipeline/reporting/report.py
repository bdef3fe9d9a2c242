"""The paper's result tables (I-IV) from our benchmark outputs, beside the paper's numbers.

Every table function is pure: it takes a pandas frame of metrics.csv rows (columns map,
planner, distance_m, steps, complete, explored_ratio, decision_ms_median, decision_ms_p95,
seed and, from `run_benchmark`, failure) and returns a frame with one row per planner
(a `planner` column, never an index) so that it can be written as markdown, DVC metrics
and MLflow runs alike. `report_markdown` assembles the tables into reports/report.md;
`log_tables_to_mlflow` logs one experiment per table and one run per row.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from pipeline.common.mlflow_store import import_mlflow, log_maze_set, resolve_tracking_uri
from pipeline.evaluation.benchmark import DEFAULT_BASELINE as PAIRED_BASELINE
from pipeline.evaluation.statistics import paired_difference
from pipeline.evaluation.predictor_eval import comparison_markdown
from pipeline.evaluation.predictor_eval import table1_markdown as predictor_table1
from pipeline.reporting.render import PANEL_GAP_RGB, render_comparison, save_png
from pipeline.world.maps import load_map
from pipeline.world.protocol import Protocol
from pipeline.world.trajectories import read_trajectory_csv

DASH = "—"
NOT_RUN = "not run"
REFERENCE_PLANNER = "optimal"
ABLATION_PLANNERS = ("guide", "guide_noregion", "guide_tsp", "dare")
K_PLANNERS = ("guide", "dare")
FIGURE_MAPS = 2

# --------------------------------------------------------------------------- paper numbers
# Table II: distance (m) to complete exploration and its gap to the optimal path (%), maze benchmark.
PAPER_TABLE2: dict[str, tuple[float, float | None]] = {
    "NBVP": (640.0, 27.7),
    "DRL": (575.0, 14.8),
    "MapEx": (571.0, 14.0),
    "DARE": (565.0, 12.8),
    "TARE": (560.0, 11.8),
    "GUIDE": (545.0, 8.8),
    "Optimal": (501.0, None),
}
# Table III: ablations, distance (m) and gap to optimal (%).
PAPER_TABLE3: dict[str, tuple[float, float | None]] = {
    "w/o region evaluation": (561.0, 11.9),
    "w/o diffusion": (580.0, 15.7),
    "GUIDE": (545.0, 8.8),
}
# Table IV: denoising steps K -> (decision time in s, distance in m), Gazebo scenes.
PAPER_TABLE4: dict[str, dict[int, tuple[float, float]]] = {
    "GUIDE": {10: (0.177, 579.0), 30: (0.227, 533.0), 50: (0.663, 532.0), 100: (1.283, 530.0)},
    "DARE": {10: (0.163, 762.0), 30: (0.211, 747.0), 50: (0.647, 724.0), 100: (1.271, 708.0)},
}
# Table V: two Gazebo scenes (3-D, 5 runs each): scene -> method -> (distance m, time s, m^3/m, m^3/s).
PAPER_TABLE5: dict[str, dict[str, tuple[float, float, float, float]]] = {
    "Scene 1 (64 x 85 m)": {"TARE": (1064.72, 585.53, 5.11, 9.29), "DRL": (741.15, 536.77, 7.34, 10.13),
                            "DARE": (681.41, 482.82, 7.98, 11.27), "GUIDE": (537.18, 432.11, 10.13, 12.59)},
    "Scene 2 (92 x 74 m)": {"TARE": (1033.72, 615.37, 6.58, 11.06), "DRL": (759.88, 635.36, 8.96, 10.72),
                            "DARE": (797.38, 623.27, 8.54, 10.93), "GUIDE": (531.37, 513.09, 12.81, 13.27)},
}
# Our registered planner names -> the paper's row names (planners without a row show DASH).
PAPER_ROWS: dict[str, str] = {
    "nbvp": "NBVP",
    "drl": "DRL",
    "drl_shipped": "DRL",  # params.yaml's label for the shipped drl policy (trained longer than the default profile's)
    "mapex": "MapEx",
    "dare": "DARE",
    "tare": "TARE",
    "guide": "GUIDE",
    "optimal": "Optimal",
    "guide_noregion": "w/o region evaluation",
    "guide_tsp": "w/o diffusion",
}
TABLE_EXPERIMENTS: dict[str, str] = {
    "table1": "table1_inference",
    "table2": "table2_benchmark",
    "table3": "table3_ablation",
    "table4": "table4_denoising_steps",
    "table5": "table5_efficiency",
}
TABLE5_COLUMNS = ("planner", "maps", "explored_m2", "distance_m", "time_s", "efficiency_m2_per_m",
                  "efficiency_m2_per_s", "distance_to_90_m", "distance_to_99_m", "coverage_auc", "reached_90", "reached_99")
REQUIRED_COLUMNS = ("map", "planner", "distance_m", "complete", "decision_ms_median", "decision_ms_p95")


def paper_row(planner: str) -> str:
    """The paper's row name for one of our planners, else DASH."""
    return PAPER_ROWS.get(str(planner), DASH)


def _paper_table2_or_3(planner: str, prefer: str = "Table III") -> tuple[float, float, str]:
    """(distance m, gap %, source) from the preferred table (Table II or III), else the other;
    NaNs and '' when the paper has no row."""
    row = paper_row(planner)
    tables = [("Table II", PAPER_TABLE2), ("Table III", PAPER_TABLE3)]
    if prefer == "Table III":
        tables.reverse()
    for source, table in tables:
        if row in table:
            distance, gap = table[row]
            return distance, (np.nan if gap is None else gap), source
    return np.nan, np.nan, ""


def check_metrics(frame: pd.DataFrame, what: str = "metrics") -> pd.DataFrame:
    """The frame with `complete` as bool; ValueError naming the missing columns."""
    missing = [c for c in REQUIRED_COLUMNS if c not in frame.columns]
    if missing:
        raise ValueError(f"{what}: missing column(s) {missing}; expected metrics.csv rows ({', '.join(REQUIRED_COLUMNS)}, ...)")
    frame = frame.copy()
    complete = frame["complete"]
    if complete.dtype == object:
        complete = complete.astype(str).str.strip().str.lower().isin(("true", "1", "yes"))
    frame["complete"] = complete.astype(bool)
    return frame


def read_metrics(path: str | Path) -> pd.DataFrame:
    """metrics.csv as a frame (checked)."""
    return check_metrics(pd.read_csv(path), str(path))


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
    "planner", "paper_row", "episodes", "distance_mean_m", "distance_std_m", "completion_rate",
    "gap_to_optimal", "vs_baseline", "vs_baseline_ci95", "decision_ms_median", "decision_ms_p95",
    "paper_distance_m", "paper_gap_pct", "paper_source",
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
        paper_distance, paper_gap, source = _paper_table2_or_3(str(planner), prefer="Table II")
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


def _num(value: Any, fmt: str = "{:.1f}", missing: str = DASH) -> str:
    try:
        number = float(value)
    except (TypeError, ValueError):
        return missing
    return fmt.format(number) if math.isfinite(number) else missing


def _mean_std(mean: Any, std: Any, episodes: Any) -> str:
    """"mean +- std", or the mean alone for a single episode (its std of 0 says nothing)."""
    one = _finite(episodes) is not None and float(episodes) < 2
    return _num(mean) if one else f"{_num(mean)} +- {_num(std)}"


def _pct(fraction: Any, signed: bool = True) -> str:
    return _num(fraction * 100.0 if fraction is not None else None, "{:+.1f} %" if signed else "{:.0f} %")


def _paper_gap(value: Any) -> str:
    return _num(value, "{:.1f} %")


def table2_markdown(table: pd.DataFrame, title: str = "Table II: exploration distance on the test mazes") -> str:
    """Markdown of `table2(...)` (a raw metrics frame is accepted too)."""
    if "distance_m" in table.columns:
        table = table2(table)
    lines = [
        f"## {title}",
        "",
        "Mean +- std distance (m) to complete exploration over the test mazes; gap = mean / mean(optimal) - 1. "
        f"`vs {PAIRED_BASELINE}`: the mean map-by-map difference to `{PAIRED_BASELINE}` as a share of its mean, "
        "+- the 95 % half-width (Student's t on the paired differences); an interval that spans 0 "
        "is a difference the test set cannot resolve. "
        "Paper: 100 test mazes (Table II; the ablations' numbers from Table III).",
        "",
        f"| planner | paper row | episodes | distance (m) | gap to optimal | vs {PAIRED_BASELINE} (paired) | complete "
        "| decision ms (median) | paper distance (m) | paper gap |",
        "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in table.itertuples(index=False):
        paired = DASH
        if row.planner != PAIRED_BASELINE and _finite(row.vs_baseline) is not None:
            paired = _pct(row.vs_baseline) + (f" +- {_num(row.vs_baseline_ci95 * 100)}" if _finite(row.vs_baseline_ci95) is not None else "")
        lines.append(
            f"| {row.planner} | {row.paper_row} | {int(row.episodes)} "
            f"| {_mean_std(row.distance_mean_m, row.distance_std_m, row.episodes)} | {_pct(row.gap_to_optimal)} | {paired} "
            f"| {_pct(row.completion_rate, signed=False)} | {_num(row.decision_ms_median, '{:.2f}')} "
            f"| {_num(row.paper_distance_m, '{:.0f}')}{' (Table III)' if row.paper_source == 'Table III' else ''} "
            f"| {_paper_gap(row.paper_gap_pct)} |"
        )
    if not table["gap_to_optimal"].notna().any():
        lines += ["", f"No `{REFERENCE_PLANNER}` episodes in the metrics, so no gap to optimal."]
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- Table III
TABLE3_COLUMNS = [
    "planner", "paper_row", "status", "episodes", "distance_mean_m", "distance_std_m", "completion_rate",
    "gap_to_optimal", "decision_ms_median", "paper_distance_m", "paper_gap_pct", "paper_source",
]


def table3(frame: pd.DataFrame, planners: Sequence[str] = ABLATION_PLANNERS) -> pd.DataFrame:
    """The ablation rows in the order given: our numbers (status "not run" and NaNs for a
    planner absent from the metrics) beside the paper's (Table III, else Table II for DARE)."""
    frame = check_metrics(frame)
    optimal = _optimal_mean(frame)
    rows = []
    for planner in planners:
        group = frame[frame["planner"] == planner]
        paper_distance, paper_gap, source = _paper_table2_or_3(planner)
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


def table3_markdown(table: pd.DataFrame, title: str = "Table III: ablations") -> str:
    """Markdown of `table3(...)`."""
    lines = [
        f"## {title}",
        "",
        "Ours on the test mazes; paper numbers from Table III (DARE, not an ablation, from Table II).",
        "",
        "| planner | variant | distance (m) | gap to optimal | complete | decision ms (median) "
        "| paper distance (m) | paper gap |",
        "|---|---|---:|---:|---:|---:|---:|---:|",
    ]
    for row in table.itertuples(index=False):
        if row.status == NOT_RUN:
            ours = f"{NOT_RUN} | {DASH} | {DASH} | {DASH}"
        else:
            ours = (
                f"{_mean_std(row.distance_mean_m, row.distance_std_m, row.episodes)} | {_pct(row.gap_to_optimal)} "
                f"| {_pct(row.completion_rate, signed=False)} | {_num(row.decision_ms_median, '{:.2f}')}"
            )
        source = f" ({row.paper_source})" if row.paper_source == "Table II" else ""
        lines.append(
            f"| {row.planner} | {row.paper_row} | {ours} "
            f"| {_num(row.paper_distance_m, '{:.0f}')}{source if np.isfinite(row.paper_distance_m) else ''} "
            f"| {_paper_gap(row.paper_gap_pct)} |"
        )
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- Table IV
TABLE4_COLUMNS = [
    "planner", "K", "label", "status", "episodes", "decision_ms_median", "decision_ms_p95",
    "distance_mean_m", "completion_rate", "paper_decision_s", "paper_distance_m",
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
                "planner": planner, "K": int(k), "label": label, "status": "ok" if len(group) else NOT_RUN,
                "episodes": int(len(group)), "paper_decision_s": paper_s, "paper_distance_m": paper_m,
            }
            if len(group):
                stats = _planner_stats(group)
                row.update({key: stats[key] for key in ("decision_ms_median", "decision_ms_p95", "distance_mean_m", "completion_rate")})
            rows.append(row)
    return pd.DataFrame(rows, columns=TABLE4_COLUMNS)


def table4_markdown(table: pd.DataFrame, title: str = "Table IV: denoising steps K") -> str:
    """Markdown of `table4(...)`."""
    lines = [
        f"## {title}",
        "",
        "Decision time: median over episodes of each episode's median (p95) planning time, over every plan() call; "
        "with T_a = 2 some calls of the diffusion planners execute a step already sampled (about 1 in 5 in the default "
        "tour mode, where a queued step is dropped once its target is reached; about half in mode policy), so the median "
        "slightly understates a full decision (graph update, prediction, K denoising steps): `benchmarks/bench_planner.py` "
        "times those alone. "
        "Paper numbers are from Gazebo scenes, ours from the test mazes of the sweep, so compare trends, not values.",
        "",
        "| planner | K | episodes | decision ms (median) | decision ms (p95) | distance (m) | complete "
        "| paper decision (s) | paper distance (m) |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in table.itertuples(index=False):
        if row.status == NOT_RUN:
            ours = f"{NOT_RUN} | {DASH} | {DASH} | {DASH}"
        else:
            ours = (
                f"{_num(row.decision_ms_median, '{:.2f}')} | {_num(row.decision_ms_p95, '{:.2f}')} "
                f"| {_num(row.distance_mean_m)} | {_pct(row.completion_rate, signed=False)}"
            )
        lines.append(
            f"| {row.planner} | {row.K} | {int(row.episodes)} | {ours} "
            f"| {_num(row.paper_decision_s, '{:.3f}')} | {_num(row.paper_distance_m, '{:.0f}')} |"
        )
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- Table I
def table5(exploration: pd.DataFrame) -> pd.DataFrame:
    """Table V on our maps from a benchmark's exploration.csv (`exploration_curves.planner_table`):
    per planner the explored area, distance, time, and the two efficiencies, best per metre first."""
    missing = [c for c in TABLE5_COLUMNS if c not in exploration.columns]
    if missing:
        raise ValueError(f"exploration table lacks {', '.join(missing)}; rerun the benchmark stage")
    table = exploration.loc[:, list(TABLE5_COLUMNS)].sort_values("efficiency_m2_per_m", ascending=False)
    return table.reset_index(drop=True)


def _reached(distance: float, reached: int, maps: int) -> str:
    """A mean distance to a share, with how many maps reached it when not all did (the done rule may stop short)."""
    return _num(distance) + ("" if int(reached) == int(maps) else f" ({int(reached)}/{int(maps)} maps)")


def table5_markdown(table: pd.DataFrame | None, speed_mps: float | None = None,
                    title: str = "Table V: exploration efficiency") -> str:
    """Ours (2-D mazes, m^2) beside the paper's (3-D Gazebo scenes, m^3): compare orderings, not values."""
    lines = [f"## {title}", ""]
    if table is None or table.empty:
        return "\n".join(lines + [f"{NOT_RUN}: the benchmark wrote no exploration.csv.", ""])
    speed = f"{speed_mps:g} m/s" if speed_mps else "the benchmark's speed"
    lines += [
        f"Ours, on the test mazes: explored free area per metre and per second of a robot at {speed} that waits "
        "while its planner decides (means of per-map ratios; distances to 90 and 99 % of the free area, and "
        "the coverage AUC, the mean explored share over each maze's longest episode).",
        "",
        "| planner | maps | explored (m^2) | distance (m) | time (s) | m^2 / m | m^2 / s | to 90 % (m) | to 99 % (m) "
        "| coverage AUC | paper row |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---|",
    ]
    for row in table.itertuples(index=False):
        lines.append(
            f"| {row.planner} | {int(row.maps)} | {_num(row.explored_m2, '{:.0f}')} | {_num(row.distance_m)} | "
            f"{_num(row.time_s)} | {_num(row.efficiency_m2_per_m, '{:.2f}')} | {_num(row.efficiency_m2_per_s, '{:.2f}')} | "
            f"{_reached(row.distance_to_90_m, row.reached_90, row.maps)} | "
            f"{_reached(row.distance_to_99_m, row.reached_99, row.maps)} | {_num(row.coverage_auc, '{:.3f}')} | "
            f"{paper_row(str(row.planner))} |"
        )
    lines += ["", "The paper's, in two 3-D Gazebo scenes (volume, m^3; 5 runs each): not comparable in value, "
              "only in ordering.", "",
              "| scene | method | distance (m) | time (s) | m^3 / m | m^3 / s |", "|---|---|---:|---:|---:|---:|"]
    for scene, methods in PAPER_TABLE5.items():
        for method, (distance, seconds, per_m, per_s) in methods.items():
            lines.append(f"| {scene} | {method} | {distance:.1f} | {seconds:.1f} | {per_m:.2f} | {per_s:.2f} |")
    return "\n".join(lines) + "\n"


def read_precision(path: str | Path) -> pd.DataFrame | None:
    """The eval_predictor stage's precision.csv, or None when it does not exist."""
    path = Path(path)
    return pd.read_csv(path) if path.is_file() else None


COMPARE_LABEL = "Another inpainter on the same explorations (eval_predictor.compare_checkpoint; by default the shipped one)"


def table1_markdown(precision: pd.DataFrame | None, compare: pd.DataFrame | None = None) -> str:
    """Table I via predictor_eval.table1_markdown, or a note that the predictor was not evaluated;
    with `compare` (precision_compare.csv, when not empty) the other inpainter's rows after it."""
    if precision is None:
        return (
            "## Table I: structural inference precision\n\n"
            f"{NOT_RUN}: reports/predictor/precision.csv is missing; run the eval_predictor stage.\n"
        )

    text = "#" + predictor_table1(precision, title="Table I: structural inference precision")
    if compare is not None and not compare.empty:
        text += "\n#" + comparison_markdown(compare, COMPARE_LABEL)
    return text


# --------------------------------------------------------------------------- figure
def trajectory_figure(
    map_paths: Sequence[str | Path],
    frame: pd.DataFrame,
    out_dir: str | Path,
    planners: Sequence[str],
    path: str | Path,
    protocol: Protocol | None = None,
    max_maps: int = FIGURE_MAPS,
) -> Path:
    """A PNG grid: one row per map (the first `max_maps` with trajectories), one panel per
    planner of `planners` that has a trajectory OUT/planner/map.csv and a metrics row.

    Raises ValueError when no listed planner has a trajectory on any of the maps.
    """
    protocol = protocol or Protocol()
    out_dir = Path(out_dir)
    frame = check_metrics(frame)
    rows = []
    for map_path in map_paths:
        if len(rows) >= max_maps:
            break
        ground_truth = load_map(map_path, cell_size=protocol.cell_size)
        on_map = frame[frame["map"].astype(str) == ground_truth.name]
        panels = []
        for planner in planners:
            match = on_map[on_map["planner"] == planner]
            csv_path = out_dir / planner / f"{ground_truth.name}.csv"
            if len(match) and csv_path.is_file():
                panels.append((planner, read_trajectory_csv(csv_path), float(match["distance_m"].iloc[0])))
        if panels:
            rows.append(render_comparison(ground_truth, panels, title=f"map {ground_truth.name}"))
    if not rows:
        raise ValueError(
            f"no trajectories of {list(planners)} under {out_dir} for maps {[Path(p).stem for p in map_paths]}"
        )
    width = max(r.shape[1] for r in rows)
    gap = 8
    blocks = []
    for i, image in enumerate(rows):
        if image.shape[1] < width:
            pad = np.empty((image.shape[0], width - image.shape[1], 3), dtype=np.uint8)
            pad[:] = PANEL_GAP_RGB
            image = np.concatenate([image, pad], axis=1)
        if i:
            spacer = np.empty((gap, width, 3), dtype=np.uint8)
            spacer[:] = PANEL_GAP_RGB
            blocks.append(spacer)
        blocks.append(image)
    return save_png(np.ascontiguousarray(np.concatenate(blocks, axis=0)), path)


# --------------------------------------------------------------------------- report
def _param_text(value: Any) -> str:
    if isinstance(value, (list, tuple)):
        return "[" + ", ".join(str(v) for v in value) + "]"
    return str(value)


def team_table_markdown(summary: Mapping[str, Mapping[str, Any]] | None, coverage_figure: str | None = None) -> str:
    """The team table: each team planner at each team size (reports/teams.json, `team_summary`),
    beside the metrics MARVEL and IR2 publish, as our team files measure them."""
    title = "## Teams: makespan by team size"
    if not summary:
        return f"{title}\n\n{NOT_RUN}: no team sizes or team planners were configured (benchmark.robots).\n"
    lines = [title, "",
             "| team planner | robots | maps | makespan (m) | total distance (m) | to 90 % (m) | vs one robot | complete |",
             "|---|---:|---:|---:|---:|---:|---:|---:|"]
    for row in summary.values():
        lines.append(f"| {row['label']} | {row['robots']} | {row['episodes']} "
                     f"| {_mean_std(row['makespan_mean_m'], row['makespan_std_m'], row['episodes'])} "
                     f"| {_num(row['total_distance_mean_m'])} | {_num(row['time_to_90_mean_m'])} "
                     f"| {_num(row['makespan_over_single_distance'], '{:.2f}')} | {_pct(row['completion_rate'], False)} |")
    lines += ["",
              "Distances and times in metres of travel (every robot at the same speed). Makespan: the team's time "
              "when the union of its beliefs is explored, which is MARVEL's trajectory length of the longest robot "
              "and IR2's maximum distance among the robots (a robot waiting still counts the time); to 90 %: "
              "MARVEL's distance to 90 % explored, in team time; vs one robot: makespan over the same planner's "
              "one-robot distance on each map (1/N is the ideal split). A planner's name is its coordinated team "
              "version; `uncoordinated_<name>` runs one planner per robot, blind to the others (docs/teams.md)."]
    if coverage_figure:
        lines += ["", f"![team coverage]({coverage_figure})"]
    return "\n".join(lines) + "\n"


def report_markdown(
    table2_frame: pd.DataFrame,
    table3_frame: pd.DataFrame,
    table4_frame: pd.DataFrame | None = None,
    precision: pd.DataFrame | None = None,
    maps: Sequence[str] = (),
    sweep_maps: Sequence[str] = (),
    protocol: Protocol | None = None,
    params: Mapping[str, Any] | None = None,
    figure: str | None = None,
    precision_compare: pd.DataFrame | None = None,
    table5_frame: pd.DataFrame | None = None,
    speed_mps: float | None = None,
    coverage_figure: str | None = None,
    teams: Mapping[str, Mapping[str, Any]] | None = None,
    team_coverage_figure: str | None = None,
) -> str:
    """reports/report.md: a header naming the maps and parameters, then Tables I-V, the team
    table and the figures."""
    lines = ["# GUIDE reimplementation: results beside the paper's", ""]
    if maps:
        lines.append(f"- Benchmark maps ({len(maps)}): {', '.join(maps)}")
    if sweep_maps:
        lines.append(f"- Denoising-steps sweep maps ({len(sweep_maps)}): {', '.join(sweep_maps)}")
    if protocol is not None:
        lines.append("- Protocol: " + ", ".join(f"{k}={v}" for k, v in protocol.to_dict().items()))
    if params:
        lines.append("- Report parameters: " + ", ".join(f"{k}={_param_text(v)}" for k, v in params.items()))
    lines.append(
        "- Paper numbers: Tables I-III on 100 test mazes, Tables IV-V in Gazebo scenes; our profile is smaller, "
        "so compare orderings and gaps rather than absolute metres."
    )
    lines.append("")
    sections = [
        table1_markdown(precision, precision_compare),
        table2_markdown(table2_frame),
        table3_markdown(table3_frame),
        table4_markdown(table4_frame) if table4_frame is not None
        else f"## Table IV: denoising steps K\n\n{NOT_RUN}: no sweep was configured.\n",
        table5_markdown(table5_frame, speed_mps),
        team_table_markdown(teams, team_coverage_figure),
    ]
    text = "\n".join(lines) + "\n" + "\n".join(sections)
    if coverage_figure:
        text += f"\n## Coverage curves\n\n![coverage curves]({coverage_figure})\n"
    if figure:
        text += f"\n## Trajectories\n\n![trajectories]({figure})\n"
    return text


def _finite(value: Any) -> float | None:
    if isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_)):
        return int(value)
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return round(number, 6) if math.isfinite(number) else None


def metrics_json(tables: Mapping[str, pd.DataFrame | None]) -> dict[str, dict[str, dict[str, float]]]:
    """{table: {row name: {numeric column: value}}}: our numbers only (the paper's constants
    and NaNs left out), the DVC metrics of report.json."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for key, table in tables.items():
        if table is None:
            continue
        rows: dict[str, dict[str, float]] = {}
        for record in table.to_dict("records"):
            values = {
                column: number
                for column, value in record.items()
                if column not in _ID_COLUMNS and not column.startswith("paper_")
                and not isinstance(value, (str, bool, np.bool_))
                and (number := _finite(value)) is not None
            }
            if values:
                rows[_run_name(record)] = values
        out[key] = rows
    return out


# --------------------------------------------------------------------------- MLflow
_ID_COLUMNS = ("planner", "K", "step", "label")


def _run_name(record: Mapping[str, Any]) -> str:
    if "step" in record and "planner" not in record:
        return f"step{int(record['step'])}"
    if "K" in record and record.get("K") is not None:
        return sweep_label(str(record["planner"]), int(record["K"]))
    return str(record["planner"])


def log_tables_to_mlflow(
    tables: Mapping[str, pd.DataFrame | None],
    tracking_uri: str | None = None,
    params: Mapping[str, Any] | None = None,
    artifacts: Mapping[str, Sequence[str | Path]] | None = None,
    maps: str | Path | None = None,
) -> dict[str, list[str]]:
    """One MLflow experiment per table, one run per row, so variants compare side by side.
    `maps`: the maze set the tables were measured on, each run's dataset input.

    Keys are "table1".."table4" (logged to table1_inference, table2_benchmark,
    table3_ablation, table4_denoising_steps) or experiment names. Run name: the planner,
    planner_kK for Table IV, stepN for Table I. Params: planner (and K / step) plus
    `params`; metrics: the row's finite numeric columns; text columns become tags; `artifacts`:
    per table key, files logged with each of its runs (Table V's coverage figure).
    Returns {experiment: [run ids]}.
    """
    mlflow = import_mlflow()

    mlflow.set_tracking_uri(resolve_tracking_uri(tracking_uri))
    run_ids: dict[str, list[str]] = {}
    for key, table in tables.items():
        if table is None:
            continue
        experiment = TABLE_EXPERIMENTS.get(key, key)
        mlflow.set_experiment(experiment)
        ids = run_ids.setdefault(experiment, [])
        for record in table.to_dict("records"):
            name = _run_name(record)
            with mlflow.start_run(run_name=name) as run:
                if maps is not None:
                    log_maze_set(maps, "evaluation")
                run_params = {column: record[column] for column in _ID_COLUMNS if column in record and column != "label"}
                mlflow.log_params({**(dict(params) if params else {}), **run_params})
                metrics = {}
                tags = {"table": key}
                for column, value in record.items():
                    if column in _ID_COLUMNS:
                        continue
                    if isinstance(value, str):
                        tags[column] = value
                    elif isinstance(value, (bool, np.bool_)):
                        metrics[column] = float(value)
                    elif (number := _finite(value)) is not None:
                        metrics[column] = number
                mlflow.set_tags(tags)
                if metrics:
                    mlflow.log_metrics(metrics)
                for path in (artifacts or {}).get(key, ()):
                    mlflow.log_artifact(str(path))
                ids.append(run.info.run_id)
    return run_ids
