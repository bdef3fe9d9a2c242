"""End to end: `dvc repro` on a fresh copy of the project with a tiny profile; the same on a
two-node Ray cluster, byte for byte; and a teammate's clone through a DVC remote."""

import json
import subprocess
from pathlib import Path

import pytest
import yaml
from tiny_project import dvc, dvc_env, git, make_tiny_project

from pipeline.planners.specs import parse_planner_spec

# The README's advice for maps at other protocol values: set them in params.yaml and rerun. A lattice
# and sensor half the maze benchmark's must run end to end and give models that record them.
HALF_SCALE = {"node_resolution": 2.0, "sensor_range": 10.0, "utility_range": 5.0, "region_size": 10.0}


@pytest.fixture(scope="module")
def tiny_repro(tiny_reference) -> tuple[Path, str]:
    """A fresh tiny copy after one `dvc repro` on the process engine, and what that run printed."""
    return tiny_reference.project, tiny_reference.output


def produced_bytes(project: Path) -> dict[str, str]:
    """DVC's hash of every data set (data/*: the collections, observations and DAgger rollouts) and
    of the gate fitted on the gate samples, and the bytes of every benchmark and report
    trajectory: what the executor's workloads made.
    (The models differ between any two runs by the training time their exports record, and the
    per-step files by the decision times.)"""
    lock = yaml.safe_load((project / "dvc.lock").read_text())
    made = {
        out["path"]: out["md5"]
        for stage in lock["stages"].values()
        for out in stage.get("outs", [])
        if out["path"].startswith(("data/", "models/sliver_gate"))
    }
    for folder in ("reports/benchmark", "reports/denoising_steps"):
        for path in sorted((project / folder).glob("*/*.csv")):
            if not path.name.endswith(".steps.csv"):
                made[str(path.relative_to(project))] = path.read_text()
    return made


@pytest.mark.slow
@pytest.mark.xdist_group("e2e")  # the shared tiny run's worker, one Ray cluster at a time
def test_every_workload_gives_the_process_engines_bytes_on_a_two_node_ray_cluster(tiny_repro, tmp_path):
    ray = pytest.importorskip("ray", reason="the ray extra is not installed (pip install -e '.[dev]' brings it)")
    from ray.cluster_utils import Cluster

    reference, _ = tiny_repro
    cluster = Cluster(initialize_head=True, head_node_args={"num_cpus": 1})
    try:
        cluster.add_node(num_cpus=1)
        cluster.wait_for_nodes()
        project = make_tiny_project(tmp_path / "project")
        env = {**dvc_env(), "GUIDE_BACKEND": "ray", "RAY_ADDRESS": cluster.address}
        run = subprocess.run(["dvc", "repro"], cwd=project, env=env, capture_output=True, text=True)
        assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    finally:
        ray.shutdown()
        cluster.shutdown()
    assert "Connecting to existing Ray cluster" in run.stdout + run.stderr  # the stages joined it
    made, expected = produced_bytes(project), produced_bytes(reference)
    assert sorted(made) == sorted(expected) and len(made) > 20
    assert {k for k in made if made[k] != expected[k]} == set()


@pytest.mark.slow
@pytest.mark.parametrize(
    "protocol", [pytest.param({}, marks=pytest.mark.xdist_group("e2e")), HALF_SCALE], ids=["default", "half_scale"]
)  # the default reads the shared tiny run; half scale runs its own
def test_dvc_repro_on_a_fresh_copy(tmp_path, protocol, request):
    if protocol:
        project = make_tiny_project(tmp_path / "project", protocol)
        env = dvc_env()
        run = subprocess.run(["dvc", "repro"], cwd=project, env=env, capture_output=True, text=True)
        assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
        printed = run.stdout + run.stderr
    else:  # the session's run (the Ray and chaos tests read it before, the remote test pushes it after)
        project, printed = request.getfixturevalue("tiny_repro")
        env = dvc_env()
    params = yaml.safe_load((project / "params.yaml").read_text())
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
    teams = json.loads((project / "reports/teams.json").read_text())
    assert sorted(teams) == ["greedy_utility@1", "greedy_utility@2", "guide_tsp@1", "guide_tsp@2"]
    assert all(row["completion_rate"] == 1.0 for row in teams.values()) and "## Teams" in report
    assert len(list((project / "reports/teams/guide_tsp@2").glob("*.team.csv"))) == 2
    assert "guide_k2" in (project / "reports/denoising_steps/metrics.csv").read_text()
    figures = (
        "reports/benchmark_distance.png",
        "reports/benchmark_trajectories.png",
        "reports/mazes_preview.png",
        "reports/pairs_preview.png",
        "reports/expert_episode.png",
        "reports/trajectories.png",
        "reports/planner_guide_curves.png",
        "reports/drl_curves.png",
        "reports/coverage.png",
        "reports/benchmark/coverage.png",
    )
    for figure in figures:
        assert (project / figure).stat().st_size > 1000
    assert (project / "mlflow.db").is_file()
    import mlflow

    client = mlflow.MlflowClient(tracking_uri=f"sqlite:///{project / 'mlflow.db'}")
    runs = [run for e in client.search_experiments() for run in client.search_runs([e.experiment_id])]
    without = sorted({run.info.run_name for run in runs if not run.inputs.dataset_inputs})
    assert len(runs) > 10 and not without, f"runs with no maze or data set recorded: {without}"
    from pipeline.models.modeling_diffusion import read_policy_export
    from pipeline.models.modeling_inpainter import read_inpainter_export
    from pipeline.world.protocol import Protocol

    trained_at = Protocol.from_dict(params["protocol"]).to_dict()
    assert read_inpainter_export(project / "models/inpainter/inpainter.pt")["protocol"] == trained_at
    assert read_policy_export(project / "models/planner_guide/policy.pt")["observations"]["protocol"] == trained_at
    assert "trained at other protocol values" not in printed  # its own models match its protocol
    again = subprocess.run(["dvc", "status"], cwd=project, env=env, capture_output=True, text=True)
    assert "up to date" in again.stdout.lower() or again.stdout.strip() == "", again.stdout
    if not protocol:  # the default case goes on with one experiment (its repro is the baseline)
        from test_dvc_experiments import check_experiments

        check_experiments(project)


@pytest.mark.slow
@pytest.mark.xdist_group("e2e")
def test_a_teammate_pulls_the_results_and_finds_nothing_to_rerun(tiny_repro, tmp_path):
    """`dvc push` to a shared remote (a local folder here; S3 or SSH in docs/scale-out.md), a fresh
    clone, `dvc pull`: `dvc status` is clean and `dvc repro` reruns nothing, also on a machine
    that sets other machine settings (workers, threads) in its params.yaml."""
    project, _ = tiny_repro
    remote = tmp_path / "remote"
    dvc(project, "remote", "add", "-d", "team", str(remote), check=True)
    dvc(project, "push", check=True)
    git(project, "add", "-A")
    git(project, "commit", "-qm", "results of the tiny profile")
    clone = tmp_path / "clone"
    git(tmp_path, "clone", "-q", str(project), str(clone))
    assert not (clone / "data/pairs").exists() and not (clone / "models/inpainter").exists()
    dvc(clone, "pull", check=True)
    status = dvc(clone, "status", check=True)
    assert "up to date" in status.stdout.lower(), status.stdout
    params = yaml.safe_load((clone / "params.yaml").read_text())
    from pipeline.common.params import MACHINE_KEYS

    changed = 0
    for section in params.values():
        for key in set(MACHINE_KEYS) & set(section if isinstance(section, dict) else ()):
            section[key] = 1 if key in ("workers", "threads", "devices") else section[key]
            changed += key in ("workers", "threads")
    assert changed >= 8
    (clone / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    status = dvc(clone, "status", check=True)
    assert "up to date" in status.stdout.lower(), status.stdout
    again = dvc(clone, "repro", check=True)
    assert "Running stage" not in again.stdout, again.stdout[-3000:]
