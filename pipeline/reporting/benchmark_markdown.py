"""The markdown a benchmark run is read by: summary.md beside metrics.csv (distance and completion
per planner, the paired difference to the baseline, the whole-building figures where the protocol
explores until done, and how fast each planner uncovers the maps) and the team summary the
command line prints.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from pipeline.common.atomic import atomic_write_text
from pipeline.evaluation.benchmark import DEFAULT_BASELINE, BenchmarkRun
from pipeline.evaluation.statistics import paired_difference, summarise
from pipeline.world.protocol import Protocol

SUMMARY_MD = "summary.md"


def write_summary(run: BenchmarkRun, out_dir: Path) -> Path:
    """summary.md of `run` in `out_dir`: its summary table, then its exploration table."""
    path = Path(out_dir) / SUMMARY_MD
    text = summary_markdown(run.frame, run.protocol_record, run.baseline, run.summary)
    atomic_write_text(path, text + "\n" + exploration_markdown(run.exploration))
    return path


def whole_building_markdown(frame: pd.DataFrame, protocol: dict[str, Any]) -> list[str]:
    """Lines of summary.md on how much of what a robot could reach each planner saw: per planner the
    mean and least share of the reachable free area explored, the early stops and the fallback
    decisions. Written when the run used the door-aware graph or a planner stopped early."""
    if not {"reachable_share", "fallbacks", "early_stop"} <= set(frame.columns):  # a frame of older metrics
        return []
    door_graph = Protocol.from_dict({k: v for k, v in protocol.items() if k != "cell_size"}).uses_door_graph
    if not door_graph and not frame["early_stop"].astype(bool).any():
        return []
    lines = [
        "",
        "The whole building (share of the free area a robot of radius "
        f"{protocol.get('robot_radius_m', 0.2):g} m reaches from the start that it saw; an early stop is a "
        "planner that said done with an unseen region of it of 1 m^2 or more left; fallbacks are decisions its own "
        "rule did not make):",
        "",
        "| planner | reachable explored (mean) | (least) | early stops | fallback decisions |",
        "|---|---:|---:|---:|---:|",
    ]
    for planner, rows in frame.groupby("planner", sort=True):
        share = rows["reachable_share"].astype(float)
        lines.append(
            f"| {planner} | {share.mean() * 100:.1f} % | {share.min() * 100:.1f} % | "
            f"{int(rows['early_stop'].astype(bool).sum())} | {int(rows['fallbacks'].sum())} |"
        )
    return lines


def summary_markdown(
    frame: pd.DataFrame,
    protocol: Protocol | dict[str, Any],
    baseline: str | None = DEFAULT_BASELINE,
    summary: pd.DataFrame | None = None,
) -> str:
    """A markdown table: mean +- std distance, completion rate, decision time per planner, and,
    when `baseline` ran too, each planner's paired difference to it (`paired_difference`).
    `protocol` is a Protocol or its record as the run wrote it (`recorded_protocol`)."""
    fields = protocol.to_dict() if isinstance(protocol, Protocol) else dict(protocol)
    summary = summarise(frame) if summary is None else summary
    has_gap = "gap_to_optimal" in summary
    has_paired = bool(baseline) and baseline in summary.index and len(summary) > 1
    gap_head = " gap to optimal |" if has_gap else ""
    paired_head = f" vs {baseline} (paired, 95 %) |" if has_paired else ""
    lines = [
        f"| planner | episodes | distance (m) |{gap_head}{paired_head} complete | decision ms (median) | decision ms (p95) |",
        "|---|---:|---:|" + ("---:|" if has_gap else "") + ("---:|" if has_paired else "") + "---:|---:|---:|",
    ]
    for planner, row in summary.iterrows():
        gap = f" {row.gap_to_optimal * 100:+.1f} % |" if has_gap else ""
        spread = f" +- {row.distance_std_m:.1f}" if row.episodes > 1 else ""  # one episode has no spread
        paired = ""
        if has_paired:
            mean, half, _ = paired_difference(frame, str(planner), str(baseline))
            if planner == baseline or not np.isfinite(mean):
                paired = " — |"
            else:
                paired = f" {mean * 100:+.1f} %" + (f" +- {half * 100:.1f} |" if np.isfinite(half) else " |")
        lines.append(
            f"| {planner} | {int(row.episodes)} | {row.distance_mean_m:.1f}{spread} |{gap}{paired}"
            f" {row.completion_rate * 100:.0f} % | {row.decision_ms_median:.2f} | {row.decision_ms_p95:.2f} |"
        )
    failures = frame[~frame["complete"].astype(bool)]
    notes = [
        "",
        "Distance is measured at completion (ground-truth free minus belief free cells "
        f"<= {fields['done_unknown_cells']}); failed episodes count with the distance they travelled.",
        *(
            [
                f"Paired: the mean map-by-map difference to {baseline} as a share of its mean, +- the 95 % half-width; "
                "an interval that spans 0 is a difference these maps cannot resolve."
            ]
            if has_paired
            else []
        ),
        "Protocol: " + ", ".join(f"{k}={v}" for k, v in fields.items()) + ".",
    ]
    notes += whole_building_markdown(frame, fields)
    if len(failures):
        notes.append("")
        notes.append(f"Failed episodes ({len(failures)}):")
        for _, row in failures.iterrows():
            notes.append(f"- {row['planner']} on {row['map']}: {row['failure'] or 'incomplete'}")
    else:
        notes.append("Every episode completed.")
    return "\n".join(lines + notes) + "\n"


def _cell(value: float, fmt: str) -> str:
    return fmt.format(value) if np.isfinite(value) else "—"


def exploration_markdown(table: pd.DataFrame) -> str:
    """The per-planner table of summary.md: how fast each planner uncovers the maps, best AUC first."""
    if table.empty:
        return ""
    levels = [c for c in table.columns if c.startswith("distance_to_")]
    heads = [f"to {c.split('_')[2]} % (m)" for c in levels]
    speed = float(table["speed_mps"].iloc[0])
    lines = [
        f"| planner | {' | '.join(heads)} | coverage AUC | m^2 / m | m^2 / s |",
        "|---|" + "---:|" * (len(levels) + 3),
    ]
    for row in table.sort_values("coverage_auc", ascending=False).itertuples(index=False):
        row = row._asdict()
        cells = []
        for column in levels:
            reached = row[f"reached_{column.split('_')[2]}"]
            text = _cell(row[column], "{:.1f}")
            cells.append(text if reached == row["maps"] else f"{text} ({reached}/{row['maps']} maps)")
        lines.append(
            f"| {row['planner']} | {' | '.join(cells)} | {_cell(row['coverage_auc'], '{:.3f}')} | "
            f"{_cell(row['efficiency_m2_per_m'], '{:.2f}')} | {_cell(row['efficiency_m2_per_s'], '{:.2f}')} |"
        )
    return (
        "\n".join(
            lines
            + [
                "",
                "To N %: the distance at the first waypoint where the known free area reaches N % of the map's "
                "(mean over the maps that reach it). Coverage AUC: the mean explored share over each map's longest "
                "episode in this comparison. m^2 / m and m^2 / s: the paper's Table V efficiency, explored area per "
                f"metre and per second of a robot at {speed:g} m/s that waits while its planner decides.",
            ]
        )
        + "\n"
    )


def team_summary_markdown(summary: dict[str, dict[str, Any]]) -> str:
    """team_summary.json as a markdown table, for the command line."""

    def cell(value: Any, fmt: str = "{:.1f}") -> str:
        return "—" if value is None else fmt.format(value)

    lines = [
        "| run | robots | episodes | makespan (m) | total distance (m) | to 90 % (m) | complete "
        "| decision ms (median) | makespan / 1-robot distance |",
        "|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for run_label, row in summary.items():
        spread = f" +- {row['makespan_std_m']:.1f}" if row["episodes"] > 1 and row["makespan_std_m"] is not None else ""
        lines.append(
            f"| {run_label} | {row['robots']} | {row['episodes']} | {cell(row['makespan_mean_m'])}{spread} "
            f"| {cell(row['total_distance_mean_m'])} | {cell(row['time_to_90_mean_m'])} "
            f"| {row['completion_rate'] * 100:.0f} % | {cell(row['decision_ms_median'], '{:.2f}')} "
            f"| {cell(row['makespan_over_single_distance'], '{:.2f}')} |"
        )
    return "\n".join(lines) + "\n"
