"""End to end: `dvc repro` on a fresh copy of the project with a tiny profile."""

import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest
import yaml

from pipeline.evaluation.benchmark import parse_planner_spec
from import_graph import ROOT



def git(cwd: Path, *args: str) -> None:
    subprocess.run(["git", "-c", "user.name=ci", "-c", "user.email=ci@example.com", *args], cwd=cwd, check=True, capture_output=True)


# The README's advice for maps at other protocol values: set them in params.yaml and rerun. A lattice
# and sensor half the maze benchmark's must run end to end and give models that record them.
HALF_SCALE = {"node_resolution": 2.0, "sensor_range": 10.0, "utility_range": 5.0, "region_size": 10.0}


@pytest.mark.slow
@pytest.mark.parametrize("protocol", [{}, HALF_SCALE], ids=["default", "half_scale"])
def test_dvc_repro_on_a_fresh_copy(tmp_path, protocol):
    if shutil.which("dvc") is None:
        pytest.fail("dvc is a dependency of the project and must be installed")
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, check=True, capture_output=True, text=True).stdout.split()
    project = tmp_path / "project"
    for name in tracked:
        if (ROOT / name).is_file():
            (project / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, project / name)
    params = yaml.safe_load((project / "params.yaml").read_text())
    params["protocol"].update(protocol)
    params["mazes"]["train"]["count"] = 2
    params["mazes"]["test"]["count"] = 2
    params["mazes"]["test"]["side_m"] = [50, 50]
    params["mazes"]["train"]["side_m"] = [50, 60]
    params["collect_pairs"].update(pairs=12, pairs_per_shard=6, stop_steps=[3, 10])
    params["collect_expert"].update(episodes=2, episodes_per_shard=1)
    params["mazes"]["offices"]["count"] = 2
    params["fit_gate"].update(maps=2, holdout_maps=1, offices=2, office_holdout=1, hidden=[4])
    params["train_inpainter"].update(max_epochs=2, batch_size=4)
    params["build_observations"].update(max_nodes=64)
    params["train_planner"]["model"].update(max_nodes=64, d_model=32, heads=2, encoder_layers=1, denoiser_layers=1)
    params["train_planner"]["train"].update(max_epochs=1, batch_size=16, warmup_steps=2)
    params["report"].update(k_values=[2, 4], k_maps=1)
    params["train_block_model"].update(mazes=3, holdout_mazes=1, side_m=50.0, epochs=1, model={"width": 8, "groups": 4})
    params["train_drl"].update(model={"max_nodes": 32, "d_model": 16, "heads": 2, "encoder_layers": 1}, timesteps=64,
                               checkpoint_every=32, eval_mazes=1, eval_side_m=50)
    params["train_drl"]["env"].update(maze_sides_m=[50], max_steps=30)
    params["train_drl"]["ppo"].update(n_envs=2, n_steps=32, batch_size=32, n_epochs=1)
    params["train_drl"]["imitation"].update(episodes=2, epochs=1, dagger_rounds=1, dagger_episodes=1, dagger_epochs=1)
    # The shipped drl policy was trained at the default protocol: its row is the benchmark's, not this copy's.
    params["benchmark"]["planners"] = [p for p in params["benchmark"]["planners"] if not p.startswith("drl_shipped=")]
    (project / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    git(project, "init", "-q")
    git(project, "add", "-A")
    git(project, "commit", "-qm", "copy")
    env = {**os.environ, "DVC_NO_ANALYTICS": "1", "MLFLOW_DISABLE_TELEMETRY": "true", "MLFLOW_TRACKING_URI": ""}
    env.pop("MLFLOW_TRACKING_URI")
    run = subprocess.run(["dvc", "repro"], cwd=project, env=env, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    assert len(list((project / "data/mazes/test").glob("*.png"))) == 2
    metrics = json.loads((project / "reports/benchmark.json").read_text())
    assert set(metrics) == {parse_planner_spec(spec).label for spec in params["benchmark"]["planners"]}
    # 64 PPO steps train no explorer: drl must run, not finish (tests/planners/baselines/test_drl.py checks the shipped one)
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
    assert drl["timesteps"] == 64 and drl["evaluation"]["mazes"] == 1 and (project / "models/drl/policy.pt").is_file()
    for variant in ("guide", "dare"):
        assert (project / f"models/planner_{variant}/policy.pt").is_file()
        assert json.loads((project / f"reports/planner_{variant}_metrics.json").read_text())["epochs"] == 1
    report = (project / "reports/report.md").read_text()
    assert "Table II" in report and "Table IV" in report and "## Table V" in report and "coverage.png" in report
    assert "guide_k2" in (project / "reports/denoising_steps/metrics.csv").read_text()
    figures = ("reports/benchmark_distance.png", "reports/benchmark_trajectories.png", "reports/mazes_preview.png",
               "reports/pairs_preview.png", "reports/expert_episode.png", "reports/trajectories.png",
               "reports/planner_guide_curves.png", "reports/drl_curves.png", "reports/coverage.png", "reports/benchmark/coverage.png")
    for figure in figures:
        assert (project / figure).stat().st_size > 1000
    assert (project / "mlflow.db").is_file()
    from pipeline.world.protocol import Protocol
    from pipeline.models.modeling_inpainter import read_inpainter_export
    from pipeline.models.modeling_diffusion import read_policy_export

    trained_at = Protocol.from_dict(params["protocol"]).to_dict()
    assert read_inpainter_export(project / "models/inpainter/inpainter.pt")["protocol"] == trained_at
    assert read_policy_export(project / "models/planner_guide/policy.pt")["observations"]["protocol"] == trained_at
    assert "trained at other protocol values" not in run.stdout + run.stderr  # its own models match its protocol
    again = subprocess.run(["dvc", "status"], cwd=project, env=env, capture_output=True, text=True)
    assert "up to date" in again.stdout.lower() or again.stdout.strip() == "", again.stdout
