import json

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from pipeline.cli import app

runner = CliRunner()


def test_planners_lists_every_name():
    result = runner.invoke(app, ["planners"])
    assert result.exit_code == 0
    for name in ("nearest_frontier", "greedy_utility", "nbvp"):
        assert name in result.output


def test_every_command_has_help():
    for command in (["--help"], ["explore", "--help"], ["benchmark", "--help"], ["replay", "--help"], ["mazes", "--help"], ["stage", "--help"]):
        result = runner.invoke(app, command)
        assert result.exit_code == 0 and "Usage" in result.output


def test_explore_writes_trajectory_metrics_png_and_gif(small_maze_path, tmp_path):
    out = tmp_path / "demo"
    result = runner.invoke(app, ["explore", "--map", str(small_maze_path), "--planner", "nearest_frontier", "--out", str(out), "--gif"])
    assert result.exit_code == 0, result.output
    for name in ("small.csv", "metrics.csv", "small.png", "small.gif"):
        assert (out / name).is_file(), name
    metrics = pd.read_csv(out / "metrics.csv")
    assert bool(metrics.loc[0, "complete"])
    replayed = runner.invoke(app, ["replay", "--map", str(small_maze_path), "--trajectory", str(out / "small.csv")])
    assert replayed.exit_code == 0
    report = json.loads(replayed.output)
    assert report["complete"] and report["distance_m"] == pytest.approx(metrics.loc[0, "distance_m"], abs=1e-3)


@pytest.mark.parametrize(
    "make_bad, reason",
    [
        (lambda d: d / "missing.png", "file not found"),
        (lambda d: (d / "junk.png").write_bytes(b"\x00garbage") and d / "junk.png", "not a readable image"),
        (lambda d: np.save(d / "cube.npy", np.ones((3, 3, 3), dtype=np.uint8)) or d / "cube.npy", "2-D"),
    ],
)
def test_bad_maps_exit_2_with_one_line(tmp_path, make_bad, reason):
    path = make_bad(tmp_path)
    result = runner.invoke(app, ["explore", "--map", str(path), "--out", str(tmp_path / "o"), "--start", "1", "1"])
    assert result.exit_code == 2
    lines = [line for line in result.output.strip().splitlines() if line]
    assert len(lines) == 1 and str(path.name) in lines[0] and reason in lines[0]
    assert "Traceback" not in result.output


def test_unknown_planner_exits_2(small_maze_path, tmp_path):
    result = runner.invoke(app, ["explore", "--map", str(small_maze_path), "--planner", "nope", "--out", str(tmp_path)])
    assert result.exit_code == 2 and "unknown planner" in result.output


def test_benchmark_command_logs_one_mlflow_run_per_planner(generated_maze_dir, tmp_path, mlflow_uri):
    out = tmp_path / "bench"
    result = runner.invoke(
        app,
        ["benchmark", "--maps", str(generated_maze_dir), "--planner", "nearest_frontier", "--planner", "greedy_utility",
         "--out", str(out), "--workers", "2", "--tracking-uri", mlflow_uri, "--experiment", "cli-test"],
    )
    assert result.exit_code == 0, result.output
    assert (out / "metrics.csv").is_file() and (out / "summary.md").is_file()
    import mlflow

    mlflow.set_tracking_uri(mlflow_uri)
    runs = mlflow.search_runs(experiment_names=["cli-test"])
    assert sorted(runs["tags.mlflow.runName"]) == ["greedy_utility", "nearest_frontier"]
    assert (runs["metrics.completion_rate"] == 1.0).all()


def test_mazes_draws_loadable_benchmark_mazes_and_refuses_a_used_folder(tmp_path):
    from pipeline.maps import load_map

    out = tmp_path / "set"
    result = runner.invoke(app, ["mazes", "--out", str(out), "--count", "2", "--seed", "5", "--side", "30"])
    assert result.exit_code == 0, result.output
    paths = sorted(out.glob("maze_*.png"))
    assert [p.name for p in paths] == ["maze_0000.png", "maze_0001.png"]
    first = load_map(paths[0])
    assert first.free.shape == (75, 75) and first.free.any()  # 30 m at 0.4 m cells
    again = runner.invoke(app, ["mazes", "--out", str(tmp_path / "again"), "--count", "1", "--seed", "5", "--side", "30"])
    assert again.exit_code == 0
    assert (tmp_path / "again" / "maze_0000.png").read_bytes() == paths[0].read_bytes()  # the seed fixes the maze
    used = runner.invoke(app, ["mazes", "--out", str(out), "--count", "1"])
    assert used.exit_code == 2 and "already holds 2 maze PNGs" in used.output
    odd = runner.invoke(app, ["mazes", "--out", str(tmp_path / "odd"), "--count", "1", "--side", "7"])
    assert odd.exit_code == 2 and "whole number" in odd.output
