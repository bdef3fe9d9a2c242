"""End to end: `dvc repro` on a fresh copy of the project with a tiny profile."""

import json
import subprocess

import pytest
import yaml
from tiny_project import dvc_env, make_tiny_project

from pipeline.planners.specs import parse_planner_spec

# The README's advice for maps at other protocol values: set them in params.yaml and rerun. A lattice
# and sensor half the maze benchmark's must run end to end and give models that record them.
HALF_SCALE = {"node_resolution": 2.0, "sensor_range": 10.0, "utility_range": 5.0, "region_size": 10.0}


@pytest.mark.slow
@pytest.mark.parametrize("protocol", [{}, HALF_SCALE], ids=["default", "half_scale"])
def test_dvc_repro_on_a_fresh_copy(tmp_path, protocol):
    project = make_tiny_project(tmp_path / "project", protocol)
    params = yaml.safe_load((project / "params.yaml").read_text())
    env = dvc_env()
    run = subprocess.run(["dvc", "repro"], cwd=project, env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    assert len(list((project / "data/mazes/test").glob("*.png"))) == 2
    metrics = json.loads((project / "reports/benchmark.json").read_text())
    assert set(metrics) == {parse_planner_spec(spec).label for spec in params["benchmark"]["planners"]}
    # 128 PPO steps train no explorer: drl must run, not finish (tests/planners/baselines/test_drl.py checks the shipped one)
    assert all(m["completion_rate"] == 1.0 for label, m in metrics.items() if label != "drl")
    assert metrics["drl"]["distance_mean_m"] > 0
    assert all(0 < m["coverage_auc"] <= 1 and m["efficiency_m2_per_m"] > 0 for m in metrics.values())
    assert json.loads((project / "reports/pairs_summary.json").read_text())["pairs"] == 12
    assert json.loads((project / "reports/expert_summary.json").read_text())["episodes"] == 2
    assert (project / "models/inpainter/inpainter.pt").is_file()
    assert "val_precision" in (project / "reports/inpainter_metrics.json").read_text()
    precision = (project / "reports/predictor/precision.csv").read_text().splitlines()
    assert precision[0] == "step,precision,predicted_nodes,maps,prediction_ms_median"
    drl = json.loads((project / "reports/drl_metrics.json").read_text())
    assert drl["timesteps"] == 128 and drl["evaluation"]["mazes"] == 1 and (project / "models/drl/policy.pt").is_file()
    for variant in ("guide", "dare"):
        assert (project / f"models/planner_{variant}/policy.pt").is_file()
        assert json.loads((project / f"reports/planner_{variant}_metrics.json").read_text())["epochs"] == 2
    report = (project / "reports/report.md").read_text()
    assert "Table II" in report and "Table IV" in report and "## Table V" in report and "coverage.png" in report
    assert "guide_k2" in (project / "reports/denoising_steps/metrics.csv").read_text()
    figures = ("reports/benchmark_distance.png", "reports/benchmark_trajectories.png", "reports/mazes_preview.png",
               "reports/pairs_preview.png", "reports/expert_episode.png", "reports/trajectories.png",
               "reports/planner_guide_curves.png", "reports/drl_curves.png", "reports/coverage.png", "reports/benchmark/coverage.png")
    for figure in figures:
        assert (project / figure).stat().st_size > 1000
    assert (project / "mlflow.db").is_file()
    from pipeline.models.modeling_diffusion import read_policy_export
    from pipeline.models.modeling_inpainter import read_inpainter_export
    from pipeline.world.protocol import Protocol

    trained_at = Protocol.from_dict(params["protocol"]).to_dict()
    assert read_inpainter_export(project / "models/inpainter/inpainter.pt")["protocol"] == trained_at
    assert read_policy_export(project / "models/planner_guide/policy.pt")["observations"]["protocol"] == trained_at
    assert "trained at other protocol values" not in run.stdout + run.stderr  # its own models match its protocol
    again = subprocess.run(["dvc", "status"], cwd=project, env=env, capture_output=True, text=True)
    assert "up to date" in again.stdout.lower() or again.stdout.strip() == "", again.stdout
    if not protocol:  # the default case goes on with one experiment (its repro is the baseline)
        from test_dvc_experiments import check_experiments

        check_experiments(project)
