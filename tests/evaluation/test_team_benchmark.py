import json
import math

import numpy as np
import pandas as pd
import pytest

import pipeline.evaluation.team_benchmark as team_benchmark
from pipeline.evaluation.benchmark import BenchmarkInterrupted
from pipeline.evaluation.team_benchmark import (
    METRICS_COLUMNS,
    ROBOT_COLUMNS,
    TEAM_KEPT_EPISODES,
    check_comm_range,
    check_robot_counts,
    run_team_benchmark,
)
from pipeline.reporting.coverage_figure import team_coverage_figure
from pipeline.reporting.team_figures import ROBOT_RGB, team_paths_figure
from pipeline.world.maps import list_maps, load_map
from pipeline.world.protocol import Protocol
from pipeline.world.team_files import merges_path, read_team_csv
from pipeline.world.team_replay import replay_team

PLANNERS = ["uncoordinated_greedy_utility", "nf=uncoordinated_nearest_frontier"]


def test_team_benchmark_writes_every_file_and_each_team_file_replays(generated_maze_dir, tmp_path):
    maps = list_maps(generated_maze_dir)[:2]
    run = run_team_benchmark(maps, PLANNERS, Protocol(), tmp_path, robots=[3, 1], workers=2, progress=False)
    metrics = pd.read_csv(tmp_path / "team_metrics.csv")
    assert list(metrics.columns) == METRICS_COLUMNS
    assert sorted(set(metrics["label"])) == [
        "nf@1",
        "nf@3",
        "uncoordinated_greedy_utility@1",
        "uncoordinated_greedy_utility@3",
    ]
    assert len(metrics) == 8 and metrics["complete"].all()
    assert set(metrics.loc[metrics["label"] == "nf@3", "planner"]) == {"uncoordinated_nearest_frontier"}
    speed = json.loads((tmp_path / "team_run.json").read_text())["speed_mps"]
    for row in metrics.itertuples():
        team_file = tmp_path / row.label / f"{row.map}.team.csv"
        rows = read_team_csv(team_file)
        replayed = replay_team(load_map(generated_maze_dir / f"{row.map}.png"), rows, Protocol())
        assert replayed.complete and not replayed.motion_violations and replayed.robots == row.robots
        assert replayed.makespan_s * speed == pytest.approx(row.makespan_m, abs=1e-3)
        assert replayed.total_distance_m == pytest.approx(row.total_distance_m, abs=1e-3)
        robots = pd.read_csv(tmp_path / row.label / f"{row.map}.robots.csv")
        assert list(robots.columns) == ROBOT_COLUMNS and list(robots["robot"]) == list(range(row.robots))
        assert robots["distance_m"].to_numpy() == pytest.approx(replayed.robot_distance_m, abs=1e-3)
        assert int(robots["moves"].sum()) == len(rows) - row.robots
        assert not merges_path(team_file).exists()  # full communication: no merges file
    coverage = pd.read_csv(tmp_path / "team_coverage.csv")
    assert list(coverage.columns) == ["label", "map", "robots", "time_m", "explored_share"]
    for (label, name), episode in coverage.groupby(["label", "map"]):
        assert (np.diff(episode["explored_share"]) >= 0).all() and (np.diff(episode["time_m"]) >= 0).all()
        assert episode["time_m"].iloc[-1] == pytest.approx(
            metrics.loc[(metrics["label"] == label) & (metrics["map"] == name), "makespan_m"].item(), abs=1e-3
        )
    summary = json.loads((tmp_path / "team_summary.json").read_text())
    assert list(summary) == ["uncoordinated_greedy_utility@1", "uncoordinated_greedy_utility@3", "nf@1", "nf@3"]
    nf3 = summary["nf@3"]
    assert nf3["robots"] == 3 and nf3["episodes"] == 2 and nf3["completion_rate"] == 1.0
    group = metrics[metrics["label"] == "nf@3"]
    assert nf3["makespan_mean_m"] == pytest.approx(group["makespan_m"].mean(), abs=1e-3)
    assert nf3["total_distance_mean_m"] == pytest.approx(group["total_distance_m"].mean(), abs=1e-3)
    single = metrics[metrics["label"] == "nf@1"].set_index("map")["total_distance_m"]
    expected = float(np.mean([r.makespan_m / single[r.map] for r in group.itertuples()]))
    assert nf3["makespan_over_single_distance"] == pytest.approx(expected, abs=1e-3)
    assert summary["nf@1"]["makespan_over_single_distance"] == 1.0
    assert not (tmp_path / TEAM_KEPT_EPISODES).exists()
    assert [task.run_label for task, _ in run.episodes][:2] == ["uncoordinated_greedy_utility@1"] * 2  # task order


def test_a_range_writes_the_merges_beside_each_team_file(generated_maze_dir, tmp_path):
    maps = list_maps(generated_maze_dir)[:2]
    run_team_benchmark(
        maps,
        ["uncoordinated_nearest_frontier"],
        Protocol(),
        tmp_path,
        robots=[3],
        comm_range_m=12.0,
        workers=1,
        progress=False,
    )
    metrics = pd.read_csv(tmp_path / "team_metrics.csv")
    assert (metrics["comm_range_m"] == 12.0).all() and (metrics["merges"] > 0).all()
    for row in metrics.itertuples():
        merges = pd.read_csv(merges_path(tmp_path / row.label / f"{row.map}.team.csv"))
        assert list(merges.columns) == ["time_s", "robots"] and len(merges) == row.merges
    assert (
        json.loads((tmp_path / "team_summary.json").read_text())["uncoordinated_nearest_frontier@3"]["comm_range_m"]
        == 12.0
    )


@pytest.mark.parametrize("counts", [[0], [9], [2, 9], [], [True], [2.5]])
def test_robot_counts_outside_1_to_8_are_refused(counts):
    with pytest.raises(ValueError, match="robot count"):
        check_robot_counts(counts)


def test_robot_counts_are_sorted_once_each():
    assert check_robot_counts([3, 1, 3, 8]) == [1, 3, 8]


@pytest.mark.parametrize("metres", [0, -3.0, math.nan, math.inf])
def test_a_range_that_is_not_a_positive_distance_is_refused(metres):
    with pytest.raises(ValueError, match="positive number of metres"):
        check_comm_range(metres)


def test_bad_planners_are_refused_before_any_file(generated_maze_dir, tmp_path):
    maps = list_maps(generated_maze_dir)[:1]
    for planners, message in (
        (["nope"], "unknown team planner 'nope'"),
        (["a=uncoordinated_greedy_utility", "a=uncoordinated_nearest_frontier"], "used twice"),
        (["g=uncoordinated_greedy_utility:no_such_option=1"], "planner 'g'"),
        (["expert"], "planner 'expert'"),
    ):
        with pytest.raises(ValueError, match=message):
            run_team_benchmark(maps, planners, Protocol(), tmp_path / "out", robots=[2], progress=False)
    with pytest.raises(ValueError, match="robot counts"):
        run_team_benchmark(
            maps, ["uncoordinated_greedy_utility"], Protocol(), tmp_path / "out", robots=[9], progress=False
        )
    assert not (tmp_path / "out").exists()


def test_a_killed_team_benchmark_resumes_with_its_kept_episodes(generated_maze_dir, tmp_path, monkeypatch):
    """Interrupted after two episodes: they stay kept; the rerun makes only the missing ones and
    writes the same files as a run never interrupted."""
    maps = list_maps(generated_maze_dir)
    arguments = dict(planners=PLANNERS, protocol=Protocol(), robots=[1, 2], workers=1, progress=False)
    finished = team_benchmark.run_team_task
    calls = []

    def interrupt_after_two(inputs, task):
        if len(calls) == 2:
            raise KeyboardInterrupt
        calls.append(task)
        return finished(inputs, task)

    monkeypatch.setattr(team_benchmark, "run_team_task", interrupt_after_two)
    killed = tmp_path / "killed"
    with pytest.raises(BenchmarkInterrupted) as stop:
        run_team_benchmark(maps, out_dir=killed, **arguments)
    assert (stop.value.done, stop.value.total) == (2, 12)
    partial = pd.read_csv(killed / "team_metrics.csv")
    assert len(partial) == 2 and len(list((killed / TEAM_KEPT_EPISODES).glob("item_*.pkl"))) == 2

    def counted(inputs, task):
        calls.append(task)
        return finished(inputs, task)

    calls.clear()
    monkeypatch.setattr(team_benchmark, "run_team_task", counted)
    run_team_benchmark(maps, out_dir=killed, **arguments)
    assert len(calls) == 10  # the two kept episodes were not run again
    resumed = pd.read_csv(killed / "team_metrics.csv")
    pd.testing.assert_frame_equal(resumed.iloc[:2], partial)  # their measured decision times too: the kept results
    assert not (killed / TEAM_KEPT_EPISODES).exists()

    whole = tmp_path / "whole"
    run_team_benchmark(maps, out_dir=whole, **arguments)
    timed = ["decision_ms_median"]
    pd.testing.assert_frame_equal(
        resumed.drop(columns=timed), pd.read_csv(whole / "team_metrics.csv").drop(columns=timed)
    )
    assert (killed / "team_coverage.csv").read_bytes() == (whole / "team_coverage.csv").read_bytes()
    team_files = sorted(p.relative_to(whole) for p in whole.glob("*/*.team.csv"))
    assert len(team_files) == 12
    for name in team_files:
        assert (killed / name).read_bytes() == (whole / name).read_bytes()


def test_team_figures_draw_each_robot_in_its_colour(generated_maze_dir, tmp_path):
    maps = list_maps(generated_maze_dir)[:1]
    run = run_team_benchmark(
        maps, ["uncoordinated_nearest_frontier"], Protocol(), tmp_path, robots=[3], workers=1, progress=False
    )
    ((task, result),) = run.episodes
    ground_truth, protocol, _ = run.maps[result.map_name]
    image = team_paths_figure(ground_truth, result.rows, protocol, tmp_path / "paths.png", title="three robots")
    assert (tmp_path / "paths.png").is_file() and image.ndim == 3
    for colour in ROBOT_RGB[:3]:
        assert (image == colour).all(axis=2).sum() > 20, colour
    assert not (image == ROBOT_RGB[3]).all(axis=2).any()  # no fourth robot
    path = team_coverage_figure(run.coverage, tmp_path / "coverage.png")
    assert path.is_file() and path.stat().st_size > 10_000
    with pytest.raises(ValueError, match="no team coverage"):
        team_coverage_figure(run.coverage.iloc[:0], tmp_path / "empty.png")
