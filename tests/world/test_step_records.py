"""The per-step record (EpisodeResult.step_rows, OUT/<label>/<map>.steps.csv): what the benchmark
writes agrees at every step with a replay of the trajectory file alone, and with an independent
reading of the protocol (tests/protocol_reference.py) on held-out generated mazes."""

from __future__ import annotations

import json

import numpy as np
import pytest
from protocol_reference import reference_explored_cells
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.evaluation.benchmark import run_benchmark
from pipeline.planners.registry import make_planner
from pipeline.world.maps import load_maze_png
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import replay, run_episode
from pipeline.world.trajectories import (
    STEP_COLUMNS,
    is_trajectory_file,
    read_steps_csv,
    read_trajectory_csv,
    steps_path,
    write_steps_csv,
)

REPLAYED = ["step", "distance_m", "explored_m2", "explored_share"]  # a replay measures no decision time


def test_step_rows_follow_the_trajectory(small_maze):
    result = run_episode(small_maze, make_planner("greedy_utility"), Protocol())
    rows = result.step_rows()
    assert result.complete and len(rows) == len(result.trajectory) == result.steps + 1
    assert [row["step"] for row in rows] == list(range(len(rows)))
    lengths = np.hypot(*np.diff(np.asarray(result.trajectory), axis=0).T)
    np.testing.assert_allclose([row["distance_m"] for row in rows], np.concatenate([[0.0], np.cumsum(lengths)]))
    assert rows[-1]["distance_m"] == result.distance_m
    shares = [row["explored_share"] for row in rows]
    assert shares == sorted(shares) and shares[-1] == pytest.approx(result.explored_ratio)
    assert rows[-1]["explored_m2"] == pytest.approx(result.explored_ratio * small_maze.free_cell_count * 0.16)
    # Each plan's time is charged to its first waypoint: the record holds every decision that moved the robot.
    assert rows[0]["decision_ms"] == 0.0
    assert sum(row["decision_ms"] for row in rows) == pytest.approx(sum(result.decision_ms))


def test_a_plan_of_several_waypoints_is_timed_once(small_maze):
    result = run_episode(small_maze, make_planner("optimal"), Protocol())  # one tour, planned at the start
    timed = [row["decision_ms"] for row in result.step_rows()]
    assert len(result.decision_ms) == 1 and timed[1] == result.decision_ms[0] and not any(timed[2:])


def test_steps_file_round_trip_and_errors(tmp_path, small_maze):
    rows = replay(small_maze, [(0, 0), (4, 0), (8, 0)], Protocol()).step_rows()
    path = write_steps_csv(tmp_path / "a.steps.csv", rows)
    assert path.read_text().splitlines()[0] == ",".join(STEP_COLUMNS)
    record = read_steps_csv(path)
    np.testing.assert_array_equal(record["step"], [0, 1, 2])
    np.testing.assert_allclose(record["explored_share"], [row["explored_share"] for row in rows], atol=1e-6)
    assert np.isnan(record["decision_ms"]).all()  # a replay has no decision times
    assert steps_path(tmp_path / "OUT/guide/maze_0001.csv") == tmp_path / "OUT/guide/maze_0001.steps.csv"
    assert is_trajectory_file(tmp_path / "maze.csv") and not is_trajectory_file(path)
    (tmp_path / "bad.csv").write_text("x,y\n0,0\n")
    with pytest.raises(ValueError, match="header step,distance_m"):
        read_steps_csv(tmp_path / "bad.csv")
    with pytest.raises(ValueError, match="file not found"):
        read_steps_csv(tmp_path / "missing.steps.csv")


@pytest.fixture(scope="module")
def held_out_run(tmp_path_factory):
    """Greedy and the oracle on two mazes no test or model has seen (their own seed), benchmarked."""
    root = tmp_path_factory.mktemp("held_out")
    maps = []
    for i in range(2):
        maps.append(
            write_maze_png(
                generate_maze(MazeConfig(side_m=(50.0, 50.0)), np.random.default_rng([90210, i])),
                root / f"maze_{i:04d}.png",
            )
        )
    run_benchmark(maps, ["greedy_utility", "optimal"], Protocol(), root / "out", workers=1, progress=False)
    return maps, root / "out"


def test_benchmark_steps_agree_with_an_independent_replay(held_out_run):
    maps, out = held_out_run
    protocol = Protocol()
    for path in maps:
        ground_truth = load_maze_png(path)
        for planner in ("greedy_utility", "optimal"):
            trajectory = read_trajectory_csv(out / planner / f"{path.stem}.csv")
            record = read_steps_csv(out / planner / f"{path.stem}.steps.csv")
            assert len(record["step"]) == len(trajectory)
            expected = reference_explored_cells(
                ground_truth.free, ground_truth.start_cell, trajectory, protocol.cell_size, protocol.sensor_range_cells
            )
            np.testing.assert_allclose(record["explored_m2"], np.asarray(expected) * protocol.cell_size**2, atol=1e-4)
            np.testing.assert_allclose(
                record["explored_share"], np.asarray(expected) / ground_truth.free_cell_count, atol=1e-6
            )
            assert np.isfinite(record["decision_ms"]).all()


def test_guide_replay_recomputes_the_benchmark_steps(held_out_run, tmp_path):
    maps, out = held_out_run
    runner = CliRunner()
    for path in maps:
        for planner, flags in (("greedy_utility", []), ("optimal", ["--oracle"])):
            mine = tmp_path / f"{planner}_{path.stem}.steps.csv"
            result = runner.invoke(
                app,
                [
                    "replay",
                    "--map",
                    str(path),
                    "--trajectory",
                    str(out / planner / f"{path.stem}.csv"),
                    "--steps-csv",
                    str(mine),
                    *flags,
                ],
            )
            assert result.exit_code == 0, result.output
            assert json.loads(result.stdout)["complete"]
            theirs = read_steps_csv(out / planner / f"{path.stem}.steps.csv")
            replayed = read_steps_csv(mine)
            for column in REPLAYED:  # every step, every column a trajectory decides
                np.testing.assert_array_equal(replayed[column], theirs[column])
            assert np.isnan(replayed["decision_ms"]).all()


def test_guide_replay_refuses_to_overwrite_the_trajectory(held_out_run):
    maps, out = held_out_run
    trajectory = out / "greedy_utility" / f"{maps[0].stem}.csv"
    result = CliRunner().invoke(
        app, ["replay", "--map", str(maps[0]), "--trajectory", str(trajectory), "--steps-csv", str(trajectory)]
    )
    assert result.exit_code == 2 and "would overwrite the trajectory" in result.output
