import pandas as pd
import pytest

from pipeline.benchmark import run_benchmark
from pipeline.maps import MapError, list_maps
from pipeline.protocol import Protocol
from pipeline.simulator import replay
from pipeline.trajectories import METRICS_COLUMNS, read_trajectory_csv
from pipeline.maps import load_map


def test_benchmark_writes_protocol_outputs_that_replay(generated_maze_dir, tmp_path):
    maps = list_maps(generated_maze_dir)[:2]
    frame = run_benchmark(maps, ["nearest_frontier", "greedy_utility"], Protocol(), tmp_path, workers=2, progress=False)
    metrics = pd.read_csv(tmp_path / "metrics.csv")
    assert list(metrics.columns) == METRICS_COLUMNS
    assert len(metrics) == 4 and metrics["complete"].all()
    assert "| nearest_frontier |" in (tmp_path / "summary.md").read_text()
    for row in metrics.itertuples():
        points = read_trajectory_csv(tmp_path / row.planner / f"{row.map}.csv")
        assert tuple(points[0]) == (0.0, 0.0)
        result = replay(load_map(generated_maze_dir / f"{row.map}.png"), points, Protocol())
        assert result.complete and result.distance_m == pytest.approx(row.distance_m, abs=1e-3)
    assert set(frame["planner"]) == {"nearest_frontier", "greedy_utility"}


def test_benchmark_rejects_unknown_planner_and_bad_maps(generated_maze_dir, tmp_path):
    with pytest.raises(KeyError, match="unknown planner"):
        run_benchmark(list_maps(generated_maze_dir), ["no_such_planner"], Protocol(), tmp_path)
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not an image")
    with pytest.raises(MapError, match="bad.png"):
        run_benchmark([bad], ["nearest_frontier"], Protocol(), tmp_path / "out")


def test_failures_are_reported_not_dropped(small_maze_path, tmp_path):
    maps = [small_maze_path]
    frame = run_benchmark(maps, ["nearest_frontier"], Protocol(max_steps=2), tmp_path, workers=1, progress=False)
    assert len(frame) == 1 and not frame["complete"].any()
    assert "step limit" in (tmp_path / "summary.md").read_text()


def test_episode_task_labels_default_to_the_planner_and_carry_options(small_maze_path):
    from pipeline.benchmark import EpisodeTask, PlannerSpec, resolve_planner_specs, run_task

    plain = EpisodeTask(str(small_maze_path), "nearest_frontier", Protocol(max_steps=2), 0)
    assert plain.label == "nearest_frontier" and plain.options == {}
    variant = EpisodeTask(str(small_maze_path), "nearest_frontier", Protocol(max_steps=2), 0, label="nf_u1", options={"min_utility": 1})
    assert run_task(variant).planner == "nf_u1"
    specs = resolve_planner_specs(["greedy_utility", PlannerSpec("nf_u1", "nearest_frontier", {"min_utility": 1})])
    assert [(s.label, s.name, s.options) for s in specs] == [
        ("greedy_utility", "greedy_utility", {}),
        ("nf_u1", "nearest_frontier", {"min_utility": 1}),
    ]
