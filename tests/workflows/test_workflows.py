"""Whole jobs: exploring one map into its files, and benchmarking a folder into its tables and MLflow runs."""

from __future__ import annotations

import json

import mlflow
import numpy as np
import pytest

from pipeline.workflows import explore
from pipeline.workflows.benchmark import benchmark_folder
from pipeline.workflows.distil_policy import observation_settings
from pipeline.world.map_files import MapError
from pipeline.world.protocol import Protocol


def test_explore_prepares_checks_and_writes_every_file(small_maze_path, tmp_path):
    run = explore.prepare(small_maze_path, "nf=nearest_frontier:min_utility=3", Protocol(), tmp_path / "out")
    assert (run.label, run.name, run.options, run.problems) == ("nf", "nearest_frontier", {"min_utility": 3}, [])
    result, written = explore.run(run, progress=False)
    assert result.complete and {path.name for path in written} == {
        "small.csv",
        "small.steps.csv",
        "metrics.csv",
        "small.png",
        "run.json",
    }
    record = json.loads((tmp_path / "out" / "run.json").read_text())
    assert record["planner"] == {
        "label": "nf",
        "name": "nearest_frontier",
        "options": {"min_utility": 3},
        "description": run.planner.description,
    }
    assert explore.summary_line(run, result).startswith("small nf: complete, ")
    assert explore.after_failure(run, result) is None
    with pytest.raises(ValueError, match="unknown planner 'nope'"):
        explore.prepare(small_maze_path, "nope", Protocol())


def test_explore_says_why_a_map_cannot_be_completed_before_the_episode(tmp_path):
    grid = np.zeros((50, 50), dtype=np.uint8)
    grid[5:35, 5:35] = 1
    grid[35:45, 35:45] = 1  # a pocket of 100 cells that touches the room at one corner: no 4-connected ray gets in
    np.save(tmp_path / "pocket.npy", grid)
    protocol = Protocol(node_resolution=2.0, sensor_range=8.0, utility_range=4.0, done_unknown_cells=20, max_steps=40)
    run = explore.prepare(tmp_path / "pocket.npy", "greedy_utility", protocol, start=(10, 10))
    assert any(
        "100 free cells are seen from no lattice node the robot can reach" in problem for problem in run.problems
    )


def test_benchmark_folder_runs_every_map_and_logs_one_run_per_planner(generated_maze_dir, tmp_path, mlflow_uri):
    said: list[str] = []
    frame = benchmark_folder(
        generated_maze_dir,
        ["nearest_frontier", "greedy_utility"],
        Protocol(),
        tmp_path / "b",
        workers=1,
        tracking_uri=mlflow_uri,
        experiment="benchmark",
        warn=said.append,
    ).frame
    assert len(frame) == 6 and frame["complete"].all() and not said
    assert "vs greedy_utility (paired, 95 %)" in (tmp_path / "b" / "summary.md").read_text()
    client = mlflow.MlflowClient(tracking_uri=mlflow_uri)
    experiment = client.get_experiment_by_name("benchmark")
    names = {run.info.run_name for run in client.search_runs([experiment.experiment_id])}
    assert {"nearest_frontier", "greedy_utility"} <= names
    with pytest.raises(ValueError, match="--baseline 'x' is not among the planners' labels"):
        benchmark_folder(
            generated_maze_dir, ["nearest_frontier"], Protocol(), tmp_path / "c", baseline="x", mlflow=False
        )
    (tmp_path / "empty").mkdir()
    with pytest.raises(MapError, match="no maps in this folder"):
        benchmark_folder(tmp_path / "empty", ["nearest_frontier"], Protocol(), tmp_path / "d", mlflow=False)


def test_distil_policy_builds_its_observations_as_the_start_policy_was_trained():
    seen = {
        "variant": "guide",
        "threshold": 0.7,
        "count_threshold": 0.4,
        "min_component": 2,
        "max_nodes": 64,
        "max_neighbors": 25,
    }
    assert observation_settings({"observations": seen}) == {k: v for k, v in seen.items() if k != "variant"}
    assert observation_settings({})["threshold"] == 0.8  # older exports: the planners' defaults
    with pytest.raises(SystemExit, match="dare observations"):
        observation_settings({"observations": {"variant": "dare"}})


def test_the_gate_fits_and_holds_out_each_kind_of_floor_in_proportion(tmp_path):
    from pipeline.workflows.fit_gate import _family_maps

    for name in [f"building_{i:04d}" for i in range(9)] + [f"plan_{i:04d}" for i in range(3)]:
        (tmp_path / f"{name}.png").write_bytes(b"")
    maps = [path.stem for path in _family_maps(tmp_path, 8, 4, "holdout_maps")]
    assert maps == ["building_0000", "building_0001", "building_0002", "plan_0000"] + [
        "building_0003",
        "building_0004",
        "building_0005",
        "plan_0001",
    ]
    only_mazes = tmp_path / "mazes"
    only_mazes.mkdir()
    for i in range(6):
        (only_mazes / f"maze_{i:04d}.png").write_bytes(b"")
    assert [p.stem for p in _family_maps(only_mazes, 4, 1, "holdout_maps")] == [f"maze_{i:04d}" for i in range(4)]
