"""summary.md beside a benchmark's metrics.csv: distance and completion per planner, the paired
difference to the baseline, and the whole-building figures where the protocol explores until
done.
"""

from __future__ import annotations

from typing import Any

import numpy as np
import pandas as pd

from pipeline.evaluation.statistics import paired_difference, summarise
from pipeline.world.protocol import Protocol

DEFAULT_BASELINE = "greedy_utility"  # summary.md's paired comparison, when it ran


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
