"""The pipeline's headline numbers: the few metrics `dvc exp show` compares across experiments.

The detailed reports (reports/report.json, reports/benchmark.json, each stage's summary) hold
hundreds of numbers; as DVC metrics they made `dvc exp show` unreadable. The `summarise` stage
keeps a handful, named for reading, in one flat-ish JSON (reports/metrics.json):

- per benchmark planner: mean distance (m), gap to `optimal` (%), and the paired difference to
  `greedy_utility` (%) with its 95 % half-width, as the report stage's Table II computed them;
- Table I: the node predictor's precision at each exploration step;
- each stage's seconds, as the stage's own summary recorded them;
- DAgger (`distil_policy`): the last round's `guide:mode=policy` against `greedy_utility` on the
  fresh mazes, the start policy's on the same mazes, and the last round's held-out agreement.

Everything here is pure: parsed JSON and CSV rows in, a dict out.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from typing import Any

# The planners the report stage measures against (pipeline.reporting.tables.REFERENCE_PLANNER and
# pipeline.evaluation.benchmark.DEFAULT_BASELINE, named again here so that this module stays light;
# tests/reporting/test_headline.py checks they agree). Their comparisons with themselves are left out.
REFERENCE_PLANNER = "optimal"
PAIRED_BASELINE = "greedy_utility"

# Table II columns of report.json -> (headline name, scale): fractions become percentages.
PLANNER_FIELDS: dict[str, tuple[str, float]] = {
    "distance_mean_m": ("distance_m", 1.0),
    "gap_to_optimal": ("gap_pct", 100.0),
    "vs_baseline": ("vs_greedy_pct", 100.0),
    "vs_baseline_ci95": ("vs_greedy_ci95_pct", 100.0),
}
GROUPS = ("precision", "seconds", "distil")  # the non-planner keys of the headline
DISTIL_STAGE = "distil_policy"  # its summary's rounds give the `distil` group


def _number(value: Any) -> float | None:
    """A finite float, or None for anything else (NaN, text, a bool, a missing value)."""
    if isinstance(value, bool) or value is None:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        return None
    return number if math.isfinite(number) else None


def planner_metrics(table2: Mapping[str, Mapping[str, Any]]) -> dict[str, dict[str, float]]:
    """Per planner (report.json's `table2`, keyed by planner label): distance, gap and paired
    difference under their headline names, rounded to 0.1. A value the report left out (NaN
    there) is left out here too, as are the reference's gap and the baseline's difference to itself."""
    out: dict[str, dict[str, float]] = {}
    for planner in sorted(table2):
        row = table2[planner]
        values: dict[str, float] = {}
        for field, (name, scale) in PLANNER_FIELDS.items():
            if planner == REFERENCE_PLANNER and field == "gap_to_optimal":
                continue
            if planner == PAIRED_BASELINE and field.startswith("vs_baseline"):
                continue
            number = _number(row.get(field))
            if number is not None:
                values[name] = round(number * scale, 1)
        if values:
            out[str(planner)] = values
    return out


def precision_by_step(rows: Iterable[Mapping[str, Any]]) -> dict[str, float]:
    """Table I's precision per exploration step from precision.csv rows (`step`, `precision`):
    {"step15": 0.748, ...} in step order, rounded to 0.001; steps without a finite precision left out."""
    found: dict[int, float] = {}
    for row in rows:
        step, precision = _number(row.get("step")), _number(row.get("precision"))
        if step is not None and precision is not None:
            found[int(step)] = round(precision, 3)
    return {f"step{step}": found[step] for step in sorted(found)}


def summary_seconds(summary: Mapping[str, Any]) -> float | None:
    """A stage summary's wall time: the sum of its top-level `seconds` and `*_seconds` numbers
    (train_block_model records collecting and training apart), or None when it records none."""
    parts = [_number(value) for key, value in summary.items() if key == "seconds" or key.endswith("_seconds")]
    numbers = [part for part in parts if part is not None]
    return round(sum(numbers), 1) if numbers else None


def stage_seconds(summaries: Mapping[str, Mapping[str, Any]]) -> dict[str, float]:
    """{stage name: seconds} for the stages whose summary records a time, in the given order."""
    out: dict[str, float] = {}
    for stage, summary in summaries.items():
        seconds = summary_seconds(summary)
        if seconds is not None:
            out[stage] = seconds
    return out


def distil_metrics(summary: Mapping[str, Any]) -> dict[str, float]:
    """The DAgger stage's few numbers from its summary's `rounds` (the start row first, then each
    round): the start's and the last round's paired difference to greedy_utility (%), and the
    last round's first-step agreement with the teacher on held-out episodes."""
    rows = [row for row in summary.get("rounds") or [] if isinstance(row, Mapping)]
    start = next((row for row in rows if row.get("round") == "start"), {})
    rounds = [row for row in rows if row.get("round") != "start"]
    last = rounds[-1] if rounds else {}
    values = {
        "rounds": _number(len(rounds) - 1) if rounds else None,  # DAgger rounds after round 0
        "start_vs_greedy_pct": _number(start.get("vs_greedy_pct")),
        "policy_vs_greedy_pct": _number(last.get("vs_greedy_pct")),
        "heldout_agreement": _number(last.get("heldout_agreement")),
    }
    return {key: round(value, 3) for key, value in values.items() if value is not None}


def headline(
    table2: Mapping[str, Mapping[str, Any]],
    precision_rows: Iterable[Mapping[str, Any]],
    summaries: Mapping[str, Mapping[str, Any]],
) -> dict[str, dict[str, Any]]:
    """The headline metrics: one key per benchmark planner (sorted), then `precision`, `seconds` and,
    when the DAgger stage's summary is among `summaries`, `distil`.

    ValueError when a planner's label is one of the group names (its column would be ambiguous)."""
    planners = planner_metrics(table2)
    clash = sorted(set(planners) & set(GROUPS))
    if clash:
        raise ValueError(f"planner label(s) {clash} clash with the headline's groups {list(GROUPS)}; relabel them")
    out = {**planners, "precision": precision_by_step(precision_rows), "seconds": stage_seconds(summaries)}
    if DISTIL_STAGE in summaries:
        out["distil"] = distil_metrics(summaries[DISTIL_STAGE])
    return out
