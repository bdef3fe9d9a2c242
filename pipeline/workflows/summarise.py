"""The headline metrics file (the `summarise` stage): the few numbers that `dvc exp show` and
`dvc metrics diff` compare, gathered from the files the other stages already write.

Reads reports/report.json (the report stage's Table II: distance, gap to optimal, paired
difference to greedy_utility), reports/predictor/precision.csv (eval_predictor's Table I) and
the summary each timed stage writes, and writes reports/metrics.json
(pipeline.reporting.headline says what it holds).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path
from typing import Any

from pipeline.common.atomic import atomic_write_json
from pipeline.common.paths import POLICIES, REPORTS
from pipeline.reporting.headline import GROUPS, headline

REPORT_JSON = REPORTS.report_metrics
PRECISION_CSV = REPORTS.predictor / "precision.csv"  # eval_predictor's Table I (pipeline/workflows/table1.py)
HEADLINE_JSON = REPORTS.headline
# Stage name (as `dvc repro` names it) -> the summary JSON in which it records its seconds.
STAGE_SUMMARIES: dict[str, Path] = {
    "fit_gate": REPORTS.sliver_gate,
    "train_block_model": REPORTS.block_model,
    "train_drl": REPORTS.drl,
    "collect_pairs": REPORTS.pairs,
    "collect_expert": REPORTS.expert,
    "train_inpainter": REPORTS.inpainter,
    "build_observations": REPORTS.observations,
    **{f"train_planner@{variant}": paths.metrics for variant, paths in POLICIES.items()},
    "distil_policy": REPORTS.distil,
}


def _missing(path: Path, stage: str) -> FileNotFoundError:
    return FileNotFoundError(f"{path} not found; run the {stage} stage first (`dvc repro {stage}`)")


def read_json(path: Path, stage: str) -> dict[str, Any]:
    """A stage's JSON object; FileNotFoundError naming the file and the stage that writes it."""
    if not path.is_file():
        raise _missing(path, stage)
    try:
        value = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: not valid JSON ({error}); rerun the {stage} stage") from None
    if not isinstance(value, dict):
        raise ValueError(f"{path}: expected a JSON object; rerun the {stage} stage")
    return value


def read_precision_rows(path: Path) -> list[dict[str, str]]:
    """precision.csv's rows (step, precision, ...)."""
    if not path.is_file():
        raise _missing(path, "eval_predictor")
    with path.open(newline="", encoding="utf-8") as handle:
        return list(csv.DictReader(handle))


def write_headline(out: Path = HEADLINE_JSON) -> dict[str, dict[str, Any]]:
    """Gather the headline metrics and write them to `out` (atomically); returns them."""
    report = read_json(REPORT_JSON, "report")
    table2 = report.get("table2")
    if not isinstance(table2, dict):
        raise ValueError(f"{REPORT_JSON}: no table2 (the benchmark's Table II); rerun the report stage")
    precision_rows = read_precision_rows(PRECISION_CSV)
    summaries = {stage: read_json(path, stage.split("@")[0]) for stage, path in STAGE_SUMMARIES.items()}
    metrics = headline(table2, precision_rows, summaries)
    atomic_write_json(out, metrics)
    planners = [key for key in metrics if key not in GROUPS]
    print(
        f"{out}: {len(planners)} planners, {len(metrics['precision'])} Table I steps, "
        f"{len(metrics['seconds'])} stage times"
    )
    return metrics
