"""The team `optimal` reference (pipeline/planners/team/team_optimal.py) on 50 m mazes."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.planners.references.coverage import run_oracle_episode
from pipeline.planners.references.coverage_model import CoverageObjective, coverage_model
from pipeline.planners.registry import make_planner
from pipeline.planners.team.registry import is_coordinated, make_team_planner
from pipeline.planners.team.team_optimal import (
    TeamOptimal,
    TeamOptimalConfig,
    covering_split,
    plan_team_coverage,
    split_viewpoints,
    team_makespan,
)
from pipeline.world.maps import list_maps, load_map
from pipeline.world.protocol import Protocol
from pipeline.world.team import run_team_episode
from pipeline.world.team_files import read_team_csv, write_team_csv
from pipeline.world.team_replay import replay_team

PROTOCOL = Protocol()
SINGLE_TOLERANCE = 0.03  # one robot's makespan against the single optimal's distance


@pytest.fixture(scope="module")
def mazes(generated_maze_dir):
    return [load_map(path) for path in list_maps(generated_maze_dir)]


@pytest.fixture(scope="module")
def team_runs(mazes):
    """Per robot count, each maze's (episode result, planner) of the team optimal."""
    runs = {}
    for robots in (1, 2, 3):
        runs[robots] = []
        for maze in mazes:
            planner = make_team_planner("optimal")
            runs[robots].append((run_team_episode(maze, planner, PROTOCOL, robots), planner))
    return runs


def test_team_optimal_is_registered_as_an_oracle_with_its_options():
    assert is_coordinated("optimal")
    planner = make_team_planner("optimal", time_limit_s=5.0, routes_time_ms=50, top_up_rounds=1)
    assert isinstance(planner, TeamOptimal)
    assert planner.uses_ground_truth and planner.ignores_motion_rule
    assert planner.config.time_limit_s == 5.0 and planner.config.routes_time_ms == 50
    with pytest.raises(ValueError, match="time_limit_s"):
        make_team_planner("optimal", time_limit_s=-1.0)


@pytest.mark.parametrize("robots", [1, 2, 3])
def test_team_optimal_completes_and_replays_clean_under_the_oracle_rule(mazes, team_runs, tmp_path, robots):
    for maze, (result, planner) in zip(mazes, team_runs[robots]):
        assert result.complete, (maze.name, result.failure)
        assert result.motion_violations == 0
        # The planned team time is the one the episode reaches: the plan is judged as the episode runs it.
        assert planner.makespan_m == pytest.approx(result.makespan_m, abs=1e-6)
        path = write_team_csv(tmp_path / f"{maze.name}.team.csv", result.rows)
        replay = replay_team(maze, read_team_csv(path), PROTOCOL, oracle=True)
        assert replay.complete and replay.motion_violations == 0, replay.failure
        assert replay.makespan_s == pytest.approx(result.makespan_m, abs=1e-3)


def test_one_robot_is_as_short_as_the_single_optimal(mazes, team_runs):
    for maze, (result, _) in zip(mazes, team_runs[1]):
        single = run_oracle_episode(maze, make_planner("optimal"), PROTOCOL)
        assert single.complete
        assert result.makespan_m <= single.distance_m * (1 + SINGLE_TOLERANCE), maze.name


def test_three_robots_finish_sooner_than_one(mazes, team_runs):
    # Never later (the single path for one robot competes), and much sooner where the maze branches
    # from the start (a generated 50 m maze may hang on one corridor, where teammates cannot help).
    sooner = []
    for maze, (one, _), (three, _) in zip(mazes, team_runs[1], team_runs[3]):
        assert three.makespan_m <= one.makespan_m + 1e-6, maze.name
        if three.makespan_m < 0.9 * one.makespan_m:
            sooner.append(maze.name)
            assert len({robot for _, robot, _, _ in three.rows[3:]}) >= 2, maze.name  # the split is driven
    assert sooner


@pytest.mark.parametrize("top_up_rounds", [0, 2])
def test_too_few_viewpoints_are_topped_up_until_the_split_completes(mazes, top_up_rounds):
    # No viewpoints at all: the greedy top-ups (or, without any, a full cover's viewpoints) must complete.
    maze = mazes[0]
    model = coverage_model(maze, PROTOCOL)
    starts = [model.start] * 3
    objective = CoverageObjective(model, np.ones(len(model.cells), dtype=bool))
    config = TeamOptimalConfig(top_up_rounds=top_up_rounds)
    assert not split_viewpoints(model, objective, starts, [], config).complete
    plan = covering_split(model, objective, starts, [], config, np.random.default_rng(0))
    assert plan.complete
    assert team_makespan(objective, plan.paths) == (plan.makespan, plan.remaining)


def test_team_paths_go_node_by_node_along_ground_truth_edges(mazes):
    model = coverage_model(mazes[0], PROTOCOL)
    plan = plan_team_coverage(model, [model.start] * 3, TeamOptimalConfig())
    assert plan.complete
    for path in plan.paths:
        assert path[0] == model.start
        for a, b in zip(path[:-1], path[1:]):
            assert model.path(a, b) == (a, b)


def test_team_makespan_counts_scans_in_time_order(mazes):
    model = coverage_model(mazes[0], PROTOCOL)
    objective = CoverageObjective(model, np.ones(len(model.cells), dtype=bool))
    makespan, remaining = team_makespan(objective, [[model.start]])
    assert makespan == float("inf") and remaining > objective.slack  # one scan at the start does not cover a maze
    far = int(np.argmax(model.dist[model.start]))
    path = model.expand([model.start, far])
    alone, _ = team_makespan(objective, [path])
    # A teammate standing still at the start adds nothing: the same time as alone.
    assert team_makespan(objective, [path, [model.start]])[0] == alone


def test_robots_from_different_starts_complete(mazes):
    maze = mazes[0]
    model = coverage_model(maze, PROTOCOL)
    other = tuple(map(float, model.world[int(np.argmax(model.dist[model.start]))]))
    result = run_team_episode(maze, make_team_planner("optimal"), PROTOCOL, 2, starts=[(0.0, 0.0), other])
    assert result.complete, result.failure
    assert replay_team(maze, result.rows, PROTOCOL, oracle=True).complete
