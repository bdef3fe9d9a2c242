"""The ground-truth coverage planners: `optimal` (oracle motion rule) and DARE's `expert`."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.planners import make_planner, planner_config, planner_names
from pipeline.planners.references import coverage as cov
from pipeline.world.geometry import segment_is_known_free
from pipeline.world.maps import load_maze_png
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import replay, run_episode

PROTOCOL = Protocol()
FAST = {"restarts": 4, "lns_iterations": 5}  # the search defaults are for benchmarks
QUICK = {"restarts": 2, "lns_iterations": 0}


@pytest.fixture(scope="module")
def generated_maze(tmp_path_factory):
    path = tmp_path_factory.mktemp("coverage_planners") / "maze.png"
    write_maze_png(generate_maze(MazeConfig(side_m=(50.0, 50.0)), np.random.default_rng([3, 6])), path)
    return load_maze_png(path)


@pytest.fixture(scope="module", params=["small", "generated"])
def maze(request, small_maze, generated_maze):
    return small_maze if request.param == "small" else generated_maze


def test_registered_as_oracles():
    assert {"optimal", "expert"} <= set(planner_names())
    assert planner_config("optimal").uses_ground_truth and planner_config("optimal").ignores_motion_rule
    assert planner_config("expert").uses_ground_truth and not planner_config("expert").ignores_motion_rule


def test_optimal_completes_under_the_oracle_rule(maze):
    planner = make_planner("optimal", **FAST)
    result = run_episode(maze, planner, PROTOCOL)
    assert result.complete and result.motion_violations == 0 and result.failure == ""
    assert result.distance_m == pytest.approx(planner.coverage.length)
    assert result.trajectory == planner.tour  # the whole tour, and not a waypoint more
    assert len(result.decision_ms) == 1
    again = cov.run_oracle_episode(maze, make_planner("optimal", **FAST), PROTOCOL)
    assert again.complete and again.distance_m == pytest.approx(result.distance_m)
    replayed = replay(maze, result.trajectory, PROTOCOL, oracle=True)
    assert replayed.complete and replayed.distance_m == pytest.approx(result.distance_m)


def test_expert_completes_through_known_space_near_optimal(maze):
    optimal = run_episode(maze, make_planner("optimal", **FAST), PROTOCOL)
    expert = run_episode(maze, make_planner("expert", **FAST), PROTOCOL)
    assert expert.complete and expert.motion_violations == 0 and expert.failure == ""
    assert expert.distance_m <= 1.15 * optimal.distance_m + 1e-6
    # its trajectory obeys the normal motion rule when replayed
    replayed = replay(maze, expert.trajectory, PROTOCOL)
    assert replayed.complete and replayed.motion_violations == 0
    assert replayed.distance_m == pytest.approx(expert.distance_m)


def test_expert_detours_when_the_next_edge_is_not_known_yet(small_maze):
    """A 6 m sensor leaves ground-truth edges unobserved: the expert must go round, legally."""
    protocol = Protocol(sensor_range=6.0, utility_range=3.0)
    optimal = run_episode(small_maze, make_planner("optimal", **QUICK), protocol)
    planner = make_planner("expert", replan_restarts=1, **QUICK)
    expert = run_episode(small_maze, planner, protocol)
    assert planner.detours > 0
    assert expert.complete and expert.motion_violations == 0
    assert expert.distance_m <= 1.15 * optimal.distance_m


def test_expert_steps_are_known_free_each_decision(small_maze):
    """Every proposed waypoint is one move whose segment is known free in the belief it saw."""
    from pipeline.world.simulator import Episode

    episode = Episode(small_maze, PROTOCOL)
    planner = make_planner("expert", **FAST)
    planner.reset(small_maze, PROTOCOL, 0)
    while not episode.complete:
        observation = episode.observe()
        waypoints = planner.plan(observation)
        assert len(waypoints) == 1
        cell = episode.waypoint_cell(waypoints[0])[0]
        assert segment_is_known_free(observation.belief == 255, episode.cell, cell)
        episode.move(waypoints[0])
        assert episode.steps < PROTOCOL.max_steps


def test_planners_are_deterministic_with_the_seed(small_maze):
    for name in ("optimal", "expert"):
        first = run_episode(small_maze, make_planner(name, **QUICK), PROTOCOL, seed=5)
        second = run_episode(small_maze, make_planner(name, **QUICK), PROTOCOL, seed=5)
        assert first.trajectory == second.trajectory


def test_expert_starts_on_the_optimal_tour(small_maze):
    """With the same seed the expert's first plan is optimal's: it takes the same first steps."""
    optimal = run_episode(small_maze, make_planner("optimal", **FAST), PROTOCOL, seed=2)
    expert = run_episode(small_maze, make_planner("expert", **FAST), PROTOCOL, seed=2)
    steps = min(3, len(optimal.trajectory))
    assert steps == 3
    assert expert.trajectory[:steps] == optimal.trajectory[:steps]


def test_expert_heads_for_where_its_plan_completes_when_no_viewpoint_is_left(small_maze, monkeypatch):
    """A plan whose scans complete the episode before its next viewpoint keeps only the robot in
    its order (cut where it completes). The expert once took that as "nothing left" and ended the
    episode as a failure with cells still to see (1 of 50 mazes when handed over mid-episode)."""
    from pipeline.planners.references import coverage_planners

    planner = make_planner("expert", **QUICK)
    planner.reset(small_maze, PROTOCOL, 0)
    robot = 0  # any local node: the plan below is made up
    path = [int(v) for v in planner.model.path(robot, len(planner.model.nodes) - 1)]
    assert len(path) > 2 and path[0] == robot
    cut = cov.CoveragePlan(order=[robot], path=path, length=12.0, complete=True, remaining=0)
    monkeypatch.setattr(coverage_planners, "plan_coverage", lambda *args, **kwargs: cut)
    planner._replan(robot, np.zeros(small_maze.free.shape, dtype=bool))
    assert planner.tour == [path[-1]]


def test_expert_under_the_door_aware_graph_plans_on_the_lattice_and_completes(tmp_path):
    # The building scale's observed graph has door nodes the coverage model has none for; a detour
    # along an edge valid only through one broke the motion rule within a few steps.
    from pipeline.world.building_config import BuildingConfig
    from pipeline.world.buildings import generate_building_set
    from pipeline.world.maps import load_map

    generate_building_set(BuildingConfig(side_m=24, cell_size=0.2), 2, tmp_path, seed=(3, 0), progress=False)
    protocol = Protocol(cell_size=0.2, node_resolution=1.0, sensor_range=10.0, done_unknown_cells=1000)
    assert protocol.uses_door_graph
    for path in sorted(tmp_path.glob("*.png")):
        result = run_episode(load_map(path, cell_size=0.2), make_planner("expert", time_limit_s=5), protocol, seed=0)
        assert result.complete and not result.failure and result.motion_violations == 0, result.failure
        positions = np.asarray(result.trajectory)
        assert np.abs(positions - np.rint(positions)).max() < 1e-6  # lattice nodes only (1 m spacing)
