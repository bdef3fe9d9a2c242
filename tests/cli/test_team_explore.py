"""`guide explore --robots N`: one team episode on one map, its files, and the flags it refuses."""

import json

import numpy as np
import pandas as pd
import pytest
from PIL import Image
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.reporting.team_figures import ROBOT_RGB
from pipeline.world.maps import load_map
from pipeline.world.protocol import Protocol
from pipeline.world.team_files import read_team_csv
from pipeline.world.team_replay import replay_team

runner = CliRunner()


def _maze(generated_maze_dir):
    return sorted(generated_maze_dir.glob("*.png"))[0]


def _explore(maze, out, *extra):
    return runner.invoke(
        app, ["explore", "--map", str(maze), "--planner", "greedy_utility", "--out", str(out), "--no-progress", *extra]
    )


def _one_error_line(result) -> str:
    assert result.exit_code == 2, result.output
    lines = [line for line in result.output.strip().splitlines() if line]
    assert len(lines) == 1, result.output
    return lines[0]


def test_a_team_explore_writes_the_team_files_and_they_replay_clean(generated_maze_dir, tmp_path):
    maze = _maze(generated_maze_dir)
    out = tmp_path / "team"
    result = _explore(maze, out, "--robots", "3", "--speed-mps", "1")
    assert result.exit_code == 0, result.output
    name = maze.stem
    for file in (f"{name}.team.csv", f"{name}.robots.csv", "team_metrics.csv", f"{name}.png", "run.json"):
        assert (out / file).is_file(), file
    assert not (out / f"{name}.team.merges.csv").exists()  # full communication: no merges file
    assert not (out / f"{name}.gif").exists()  # only with --gif
    metrics = pd.read_csv(out / "team_metrics.csv")
    assert len(metrics) == 1 and metrics.loc[0, "label"] == "greedy_utility@3" and metrics.loc[0, "robots"] == 3
    assert bool(metrics.loc[0, "complete"])
    rows = read_team_csv(out / f"{name}.team.csv")
    replay = replay_team(load_map(maze), rows, Protocol())
    assert replay.complete and replay.robots == 3 and replay.motion_violations == 0
    # At 1 m/s the file's seconds are the team's metres: the replay's makespan is the episode's.
    assert replay.makespan_s == pytest.approx(metrics.loc[0, "makespan_m"], abs=1e-3)
    assert replay.total_distance_m == pytest.approx(metrics.loc[0, "total_distance_m"], abs=1e-3)
    robots = pd.read_csv(out / f"{name}.robots.csv")
    assert list(robots["robot"]) == [0, 1, 2]
    assert robots["distance_m"].to_numpy() == pytest.approx(replay.robot_distance_m, abs=1e-3)
    record = json.loads((out / "run.json").read_text())
    assert record["map"] == str(maze) and record["robots"] == 3 and record["comm_range_m"] is None
    assert record["planner"]["name"] == "greedy_utility" and record["protocol"]["sensor_range"] == 20.0
    summary = [line for line in result.output.splitlines() if line.startswith(f"{name} greedy_utility@3:")]
    assert len(summary) == 1 and "complete" in summary[0] and "makespan" in summary[0]
    assert f"total {metrics.loc[0, 'total_distance_m']:.1f} m" in summary[0]


def test_a_team_file_times_follow_the_speed(generated_maze_dir, tmp_path):
    maze = _maze(generated_maze_dir)
    slow, fast = tmp_path / "slow", tmp_path / "fast"
    assert _explore(maze, slow, "--robots", "2", "--speed-mps", "1").exit_code == 0
    assert _explore(maze, fast, "--robots", "2").exit_code == 0  # the benchmark's default, 2 m/s
    slow_rows, fast_rows = read_team_csv(slow / f"{maze.stem}.team.csv"), read_team_csv(fast / f"{maze.stem}.team.csv")
    assert len(slow_rows) == len(fast_rows) > 2
    assert [t for t, *_ in fast_rows] == pytest.approx([t / 2 for t, *_ in slow_rows], abs=1e-5)


def test_the_team_gif_has_frames_with_every_robots_colour(generated_maze_dir, tmp_path):
    maze = _maze(generated_maze_dir)
    out = tmp_path / "gif"
    result = _explore(maze, out, "--robots", "3", "--gif")
    assert result.exit_code == 0, result.output
    with Image.open(out / f"{maze.stem}.gif") as gif:
        assert gif.n_frames >= 5
        frames = []
        for index in (0, gif.n_frames - 1):
            gif.seek(index)
            frames.append(np.asarray(gif.convert("RGB"), dtype=np.int16))
    first, last = frames
    assert first.shape == last.shape and not np.array_equal(first, last)  # the robots move between frames

    def shows(image: np.ndarray, colour: tuple[int, int, int]) -> bool:
        return int((np.abs(image - np.asarray(colour)).max(axis=2) <= 12).sum()) > 50

    for colour in ROBOT_RGB[:3]:
        assert shows(last, colour), colour
    assert not shows(last, ROBOT_RGB[4])  # a fifth robot's colour only with a fifth robot


def test_a_communication_range_writes_the_merges(generated_maze_dir, tmp_path):
    maze = _maze(generated_maze_dir)
    out = tmp_path / "range"
    result = _explore(maze, out, "--robots", "2", "--comm-range", "15")
    assert result.exit_code in (0, 1), result.output
    merges = pd.read_csv(out / f"{maze.stem}.team.merges.csv")
    assert list(merges.columns) == ["time_s", "robots"] and len(merges) >= 1
    metrics = pd.read_csv(out / "team_metrics.csv")
    assert metrics.loc[0, "comm_range_m"] == 15 and metrics.loc[0, "merges"] == len(merges)
    assert json.loads((out / "run.json").read_text())["comm_range_m"] == 15


def test_a_team_that_does_not_complete_exits_1_with_its_files_written(generated_maze_dir, tmp_path):
    maze = _maze(generated_maze_dir)
    out = tmp_path / "short"
    result = _explore(maze, out, "--robots", "2", "--max-steps", "1")
    assert result.exit_code == 1, result.output
    assert "INCOMPLETE (step limit" in result.output
    assert not bool(pd.read_csv(out / "team_metrics.csv").loc[0, "complete"])
    assert (out / f"{maze.stem}.team.csv").is_file() and (out / f"{maze.stem}.png").is_file()


def test_the_default_folder_is_named_by_label_and_robots(generated_maze_dir, tmp_path, monkeypatch):
    maze = _maze(generated_maze_dir)
    monkeypatch.chdir(tmp_path)
    result = runner.invoke(
        app,
        [
            "explore",
            "--map",
            str(maze),
            "--planner",
            "u=uncoordinated_greedy_utility",
            "--robots",
            "2",
            "--no-progress",
        ],
    )
    assert result.exit_code == 0, result.output
    assert (tmp_path / "runs" / "explore" / "u@2" / f"{maze.stem}.team.csv").is_file()


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--robots", "0"], "--robots takes a team size 1-8, got 0"),
        (["--robots", "9"], "--robots takes a team size 1-8, got 9"),
        (["--robots", "2", "--comm-range", "0"], "--comm-range takes a positive number of metres"),
        (["--robots", "2", "--comm-range", "-5"], "--comm-range takes a positive number of metres"),
        (["--comm-range", "10"], "give the team size with --robots"),
        (["--speed-mps", "1"], "give the team size with --robots"),
        (["--robots", "2", "--speed-mps", "0"], "--speed-mps"),
        (["--robots", "2", "--bag", "x.mcap"], "not supported for teams"),
        (["--robots", "2", "--planner", "no_such_planner"], "no_such_planner"),
    ],
)
def test_bad_team_flags_are_refused_in_one_line_before_any_work(generated_maze_dir, tmp_path, extra, message):
    out = tmp_path / "o"
    args = ["explore", "--map", str(_maze(generated_maze_dir)), "--out", str(out), "--no-progress", *extra]
    line = _one_error_line(runner.invoke(app, args))
    assert line.startswith("error: ") and message in line
    assert not out.exists() or not any(out.iterdir())


def test_explore_without_robots_writes_the_single_robot_files_only(generated_maze_dir, tmp_path):
    maze = _maze(generated_maze_dir)
    out = tmp_path / "single"
    result = runner.invoke(
        app, ["explore", "--map", str(maze), "--planner", "greedy_utility", "--out", str(out), "--no-progress"]
    )
    assert result.exit_code == 0, result.output
    name = maze.stem
    assert sorted(p.name for p in out.iterdir()) == sorted(
        [f"{name}.csv", f"{name}.steps.csv", "metrics.csv", f"{name}.png", "run.json"]
    )
    assert "robots" not in json.loads((out / "run.json").read_text())
    assert "robot" not in pd.read_csv(out / f"{name}.csv").columns
