"""Markdown of every result table: Tables I-V and the team table, each beside the paper's numbers,
and reports/report.md that assembles them."""

from __future__ import annotations

import math
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from pipeline.evaluation.predictor_eval import DETAIL_COLUMNS, EXPLORER, PAPER_PRECISION, PAPER_PREDICTION_MS
from pipeline.reporting.paper_numbers import DASH, PAPER_TABLE5, paper_row
from pipeline.reporting.tables import NOT_RUN, PAIRED_BASELINE, REFERENCE_PLANNER, finite_number, table2
from pipeline.world.protocol import Protocol

COMPARE_LABEL = (
    "Another inpainter on the same explorations (eval_predictor.compare_checkpoint; by default the shipped one)"
)
TABLE1_TITLE = "Table I: structural inference precision"


def _num(value: Any, fmt: str = "{:.1f}", missing: str = DASH) -> str:
    try:
        number = float(value)
    except (TypeError, ValueError):
        return missing
    return fmt.format(number) if math.isfinite(number) else missing


def _mean_std(mean: Any, std: Any, episodes: Any) -> str:
    """ "mean +- std", or the mean alone for a single episode (its std of 0 says nothing)."""
    one = finite_number(episodes) is not None and float(episodes) < 2
    return _num(mean) if one else f"{_num(mean)} +- {_num(std)}"


def _pct(fraction: Any, signed: bool = True) -> str:
    return _num(fraction * 100.0 if fraction is not None else None, "{:+.1f} %" if signed else "{:.0f} %")


def _paper_gap(value: Any) -> str:
    return _num(value, "{:.1f} %")


# --------------------------------------------------------------------------- Table I
def table1_markdown(
    precision: pd.DataFrame | None,
    compare: pd.DataFrame | None = None,
    *,
    title: str = TABLE1_TITLE,
    threshold: float | None = None,
    level: int = 2,
) -> str:
    """Table I: our precision of V_u per step beside the paper's (precision.csv's rows), under a
    heading of `level`; `threshold` (tau), when given, is named in the text. With `compare`
    (precision_compare.csv, when not empty) the other inpainter's rows follow one level down.
    Without `precision`, a note that the predictor was not evaluated."""
    heading = "#" * level
    if precision is None:
        return f"{heading} {title}\n\n{NOT_RUN}: reports/predictor/precision.csv is missing; run the eval_predictor stage.\n"
    at_tau = "" if threshold is None else f" Predicted free at P(free) >= tau = {threshold:g}."
    lines = [
        f"{heading} {title}",
        "",
        "Nodes of V_u (region-evaluated predictions and centroid nodes) that are free in the ground "
        "truth, pooled over maps, as the paper's Pre(k) = |V_u ∩ free| / |V_u|; `predictions only` leaves the "
        f"centroids out. Exploration by `{EXPLORER}`.{at_tau}",
        "",
        "Paper (100 mazes): step "
        + "/".join(str(s) for s in PAPER_PRECISION)
        + " = "
        + "/".join(f"{v:.2f}" for v in PAPER_PRECISION.values())
        + f" %, prediction {PAPER_PREDICTION_MS[0]}-{PAPER_PREDICTION_MS[1]} ms.",
        "",
        "Base rate: the free share of the nodes the network was asked about (unknown in its input) in the "
        "regions whose predictions are kept, what calling them all free would score.",
        "",
        "| step | precision (ours) | precision (paper) | base rate | V_u nodes | of them centroids | predictions only "
        "| maps | prediction ms (median, ours) |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]

    def percent(value: float) -> str:
        return "n/a" if not np.isfinite(value) else f"{100.0 * value:.2f} %"

    def count(value: float) -> str:
        return "n/a" if not np.isfinite(value) else str(int(value))

    frame = precision.reindex(columns=list(DETAIL_COLUMNS))  # precision.csv alone: the centroid columns read n/a
    for row in frame.itertuples(index=False):
        paper = f"{PAPER_PRECISION[row.step]:.2f} %" if row.step in PAPER_PRECISION else "-"
        ms = "n/a" if not np.isfinite(row.prediction_ms_median) else f"{row.prediction_ms_median:.2f}"
        lines.append(
            f"| {row.step} | {percent(row.precision)} | {paper} | {percent(row.base_rate)} | {count(row.predicted_nodes)} "
            f"| {count(row.centroids)} "
            f"| {percent(row.predictions_precision)} | {row.maps} | {ms} |"
        )
    text = "\n".join(lines) + "\n"
    if compare is not None and not compare.empty:
        text += "\n" + comparison_markdown(compare, COMPARE_LABEL, level=level + 1)
    return text


def comparison_markdown(frame: pd.DataFrame, label: str, level: int = 2) -> str:
    """Another inpainter's Table I on the same explorations, beside the paper's: a section for table1.md."""
    lines = [
        f"{'#' * level} {label}",
        "",
        "The same test mazes, explorations, tau and region evaluation; only the network differs.",
        "",
        "| step | precision | paper | at least the paper's | V_u nodes per map | prediction ms (median) |",
        "|---:|---:|---:|---|---:|---:|",
    ]
    for row in frame.itertuples(index=False):
        paper = PAPER_PRECISION.get(row.step)
        ok = (
            "-"
            if paper is None or not np.isfinite(row.precision)
            else ("yes" if 100.0 * row.precision >= paper else "no")
        )
        per_map = row.predicted_nodes / row.maps if row.maps else float("nan")
        lines.append(
            f"| {row.step} | {'n/a' if not np.isfinite(row.precision) else f'{100.0 * row.precision:.2f} %'} "
            f"| {'-' if paper is None else f'{paper:.2f} %'} | {ok} | {per_map:.1f} | {row.prediction_ms_median:.2f} |"
        )
    return "\n".join(lines) + "\n"


def sweep_markdown(sweep: pd.DataFrame) -> str:
    """Precision and |V_u| per map at each tau and step, as a markdown table."""
    steps = sorted(sweep["step"].unique())
    lines = [
        "## Precision against tau",
        "",
        "The same exploration and network, other thresholds: precision of V_u, and in brackets its "
        "nodes per map (the fewer the nodes, the less the planners have to go on).",
        "",
        "| tau | " + " | ".join(f"step {s}" for s in steps) + " |",
        "|---:|" + "---:|" * len(steps),
    ]
    for tau, group in sweep.groupby("threshold", sort=True):
        by_step = group.set_index("step")
        cells = []
        for s in steps:
            row = by_step.loc[s]
            cells.append(
                "n/a" if not np.isfinite(row.precision) else f"{100 * row.precision:.1f} % ({row.nodes_per_map:.1f})"
            )
        lines.append(f"| {tau:g} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- Tables II-V
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
        if row.planner != PAIRED_BASELINE and finite_number(row.vs_baseline) is not None:
            paired = _pct(row.vs_baseline) + (
                f" +- {_num(row.vs_baseline_ci95 * 100)}" if finite_number(row.vs_baseline_ci95) is not None else ""
            )
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


def _reached(distance: float, reached: int, maps: int) -> str:
    """A mean distance to a share, with how many maps reached it when not all did (the done rule may stop short)."""
    return _num(distance) + ("" if int(reached) == int(maps) else f" ({int(reached)}/{int(maps)} maps)")


def table5_markdown(
    table: pd.DataFrame | None, speed_mps: float | None = None, title: str = "Table V: exploration efficiency"
) -> str:
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
    lines += [
        "",
        "The paper's, in two 3-D Gazebo scenes (volume, m^3; 5 runs each): not comparable in value, only in ordering.",
        "",
        "| scene | method | distance (m) | time (s) | m^3 / m | m^3 / s |",
        "|---|---|---:|---:|---:|---:|",
    ]
    for scene, methods in PAPER_TABLE5.items():
        for method, (distance, seconds, per_m, per_s) in methods.items():
            lines.append(f"| {scene} | {method} | {distance:.1f} | {seconds:.1f} | {per_m:.2f} | {per_s:.2f} |")
    return "\n".join(lines) + "\n"


# --------------------------------------------------------------------------- teams and the report
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
    lines = [
        title,
        "",
        "| team planner | robots | maps | makespan (m) | total distance (m) | to 90 % (m) | vs one robot | complete |",
        "|---|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for row in summary.values():
        lines.append(
            f"| {row['label']} | {row['robots']} | {row['episodes']} "
            f"| {_mean_std(row['makespan_mean_m'], row['makespan_std_m'], row['episodes'])} "
            f"| {_num(row['total_distance_mean_m'])} | {_num(row['time_to_90_mean_m'])} "
            f"| {_num(row['makespan_over_single_distance'], '{:.2f}')} | {_pct(row['completion_rate'], False)} |"
        )
    lines += [
        "",
        "Distances and times in metres of travel (every robot at the same speed). Makespan: the team's time "
        "when the union of its beliefs is explored, which is MARVEL's trajectory length of the longest robot "
        "and IR2's maximum distance among the robots (a robot waiting still counts the time); to 90 %: "
        "MARVEL's distance to 90 % explored, in team time; vs one robot: makespan over the same planner's "
        "one-robot distance on each map (1/N is the ideal split). A planner's name is its coordinated team "
        "version; `uncoordinated_<name>` runs one planner per robot, blind to the others (docs/teams.md).",
    ]
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
        table4_markdown(table4_frame)
        if table4_frame is not None
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
