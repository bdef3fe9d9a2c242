"""The summarise stage: reports/metrics.json from the report, Table I and the stage summaries; one error line without them."""

from __future__ import annotations

import json

import pytest

from pipeline.common.paths import REPORTS
from pipeline.stage_runner import run_stage_main
from pipeline.workflows import summarise as workflow
from stages import summarise


def write_upstream(root) -> None:
    """The files summarise reads, small and made up, under `root` (a project folder)."""
    report = {
        "table2": {
            "guide": {"distance_mean_m": 480.0, "gap_to_optimal": 0.4, "vs_baseline": -0.02, "vs_baseline_ci95": 0.09},
            "optimal": {"distance_mean_m": 342.0, "gap_to_optimal": 0.0},
        },
        "table1": {"step15": {"precision": 0.7}},
    }
    (root / workflow.REPORT_JSON).parent.mkdir(parents=True, exist_ok=True)
    (root / workflow.REPORT_JSON).write_text(json.dumps(report))
    (root / workflow.PRECISION_CSV).parent.mkdir(parents=True, exist_ok=True)
    (root / workflow.PRECISION_CSV).write_text(
        "step,precision,predicted_nodes,maps,prediction_ms_median\n15,0.75,111,12,2.4\n30,0.5,89,12,3.0\n"
    )
    for number, path in enumerate(workflow.STAGE_SUMMARIES.values()):
        (root / path).write_text(json.dumps({"seconds": float(number + 1)}))


def test_the_stage_writes_the_headline_file(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    write_upstream(tmp_path)
    summarise.main()
    metrics = json.loads((tmp_path / REPORTS.headline).read_text())
    assert metrics["guide"] == {"distance_m": 480.0, "gap_pct": 40.0, "vs_greedy_pct": -2.0, "vs_greedy_ci95_pct": 9.0}
    assert metrics["optimal"] == {"distance_m": 342.0}
    assert metrics["precision"] == {"step15": 0.75, "step30": 0.5}
    assert list(metrics["seconds"]) == list(workflow.STAGE_SUMMARIES)
    assert {"train_planner@guide", "train_planner@dare", "train_inpainter"} <= set(metrics["seconds"])


@pytest.mark.parametrize(
    "missing, stage",
    [
        (workflow.REPORT_JSON, "report"),
        (workflow.PRECISION_CSV, "eval_predictor"),
        (REPORTS.block_model, "train_block_model"),
    ],
)
def test_a_missing_upstream_file_is_one_error_line_naming_it(tmp_path, monkeypatch, capsys, missing, stage):
    monkeypatch.chdir(tmp_path)
    write_upstream(tmp_path)
    (tmp_path / missing).unlink()
    with pytest.raises(SystemExit) as exit_info:
        run_stage_main(summarise.main)
    assert exit_info.value.code == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert lines == [f"error: {missing} not found; run the {stage} stage first (`dvc repro {stage}`)"]
    assert not (tmp_path / REPORTS.headline).exists()


def test_a_report_without_table2_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    write_upstream(tmp_path)
    (tmp_path / workflow.REPORT_JSON).write_text("{}")
    with pytest.raises(ValueError, match="table2"):
        summarise.main()
