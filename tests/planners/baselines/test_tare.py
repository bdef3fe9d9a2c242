"""Tests of the TARE planner (pipeline/planners/tare.py): its parts and whole episodes."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.lattice.frontier import frontier_mask
from pipeline.lattice.visibility import visible_counts
from pipeline.planners import make_planner, planner_names
from pipeline.planners.baselines.tare import TareConfig, TarePlanner, greedy_set_cover, visible_frontier_cells
from pipeline.planners.wrapper import innermost
from pipeline.world.maps import GroundTruthMap, load_maze_png
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.planner import Observation
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN
from pipeline.world.simulator import Episode, replay, run_episode

PROTOCOL = Protocol()


# A 65 m maze of 5 m blocks ('#' wall, '.' free, 'S' start) with dead ends and a loop:
# long enough (about 80 decisions) for both levels of the planner to take turns.
BLOCKS = [
    "#############",
    "#S....#.....#",
    "#.###.#.###.#",
    "#.#...#...#.#",
    "#.#.#####.#.#",
    "#...#.....#.#",
    "###.#.###.#.#",
    "#...#...#...#",
    "#.#####.###.#",
    "#.....#.....#",
    "#.###.#.#####",
    "#...#.......#",
    "#############",
]


def block_maze_png(blocks: list[str], path, block_px: int = 25) -> GroundTruthMap:
    values = {"#": 127, ".": 195, "S": 208}  # wall, free, start in the maze PNG format
    image = np.full((len(blocks) * block_px, len(blocks[0]) * block_px), values["#"], dtype=np.uint8)
    for r, line in enumerate(blocks):
        for c, char in enumerate(line):
            image[r * block_px : (r + 1) * block_px, c * block_px : (c + 1) * block_px] = values[char]
    write_maze_png(image, path)
    return load_maze_png(path)


@pytest.fixture(scope="module")
def maze(tmp_path_factory) -> GroundTruthMap:
    return block_maze_png(BLOCKS, tmp_path_factory.mktemp("tare") / "blocks.png")


@pytest.fixture(scope="module")
def result(maze):
    return run_episode(maze, make_planner("tare"), PROTOCOL)


@pytest.fixture(scope="module")
def generated_maze(tmp_path_factory) -> GroundTruthMap:
    """A generated 50 m maze in the benchmark's PNG format."""
    path = tmp_path_factory.mktemp("tare") / "maze_50m.png"
    write_maze_png(generate_maze(MazeConfig(side_m=(50.0, 50.0)), np.random.default_rng(3)), path)
    return load_maze_png(path)


# --------------------------------------------------------------------------- visibility
def test_visible_frontier_cells_on_a_hand_made_belief():
    belief = np.full((60, 60), FREE, dtype=np.uint8)
    belief[0, :] = belief[-1, :] = belief[:, 0] = belief[:, -1] = OCCUPIED
    belief[4:17, 20] = OCCUPIED  # a wall across the x axis, 10 cells right of the origin
    frontier = np.zeros(belief.shape, dtype=bool)
    frontier[10, 15] = True  # in front of the wall, 5 cells away: seen
    frontier[10, 22] = True  # behind the wall: hidden
    frontier[45, 10] = True  # 35 cells below: beyond the 25-cell range
    frontier[10, 5] = True  # 5 cells to the left: seen
    origin = np.array([[10, 10]])  # (col, row)
    (seen,) = visible_frontier_cells(belief == FREE, frontier, origin, 25.0)
    assert seen.tolist() == sorted([10 * 60 + 15, 10 * 60 + 5])
    # From below the wall's end the hidden cell comes into view.
    (seen_below,) = visible_frontier_cells(belief == FREE, frontier, np.array([[22, 30]]), 25.0)
    assert 10 * 60 + 22 in seen_below.tolist()


def test_visible_frontier_cells_match_the_graph_utility_counts():
    rng = np.random.default_rng(5)
    belief = np.full((70, 90), UNKNOWN, dtype=np.uint8)
    belief[5:60, 5:80] = FREE
    belief[rng.random(belief.shape) < 0.04] = OCCUPIED
    belief[30:, 45:] = UNKNOWN
    frontier = frontier_mask(belief)
    origins = np.array([[10, 10], [40, 25], [44, 29], [70, 12], [20, 50], [2, 2]])
    sets = visible_frontier_cells(belief == FREE, frontier, origins, 25.0)
    counts = visible_counts(belief == FREE, frontier, origins, 25.0)
    assert [len(s) for s in sets] == counts.tolist()
    assert sum(len(s) for s in sets) > 0
    for s in sets:
        assert frontier.reshape(-1)[s].all()
        assert np.all(np.diff(s) > 0)


# --------------------------------------------------------------------------- cover
def test_greedy_set_cover():
    sets = [np.array([1, 2, 3]), np.array([3, 4]), np.array([4, 5, 6, 7]), np.array([1, 2]), np.array([9])]
    cost = np.array([5.0, 1.0, 2.0, 0.5, 1.0])
    # {4,5,6,7} first (4 new), then {1,2,3} (3 new); {9} adds 1 < min_cover 2.
    assert greedy_set_cover(sets, cost, min_cover=2) == [2, 0]
    assert greedy_set_cover(sets, cost, min_cover=1) == [2, 0, 4]
    # A tie on new cells goes to the cheaper set.
    assert greedy_set_cover([np.array([1, 2]), np.array([3, 4])], np.array([3.0, 1.0]), 1) == [1, 0]
    assert greedy_set_cover([], np.zeros(0), 1) == []


# --------------------------------------------------------------------------- the planner
def test_registered_with_a_description():
    assert "tare" in planner_names()
    planner = make_planner("tare")
    assert isinstance(innermost(planner), TarePlanner)  # inside the whole building's wrapper
    assert planner.name == "tare" and planner.description


def test_completes_without_motion_violations(maze, result):
    assert result.complete, result.failure
    assert result.motion_violations == 0
    assert 20 < result.steps < PROTOCOL.max_steps
    again = replay(maze, result.trajectory, PROTOCOL)
    assert again.complete and again.motion_violations == 0
    assert again.distance_m == pytest.approx(result.distance_m)


def test_completes_a_generated_maze(generated_maze):
    first = run_episode(generated_maze, make_planner("tare"), PROTOCOL)
    assert first.complete, first.failure
    assert first.motion_violations == 0
    again = run_episode(generated_maze, make_planner("tare"), PROTOCOL)
    assert again.trajectory == first.trajectory


def test_deterministic(maze, result):
    again = run_episode(maze, make_planner("tare"), PROTOCOL, seed=5)
    assert again.trajectory == result.trajectory
    assert again.distance_m == result.distance_m


def test_one_lattice_step_per_decision(maze):
    planner = make_planner("tare")
    planner.reset(maze, PROTOCOL, 0)
    episode = Episode(maze, PROTOCOL)
    modes = set()
    while not episode.complete and episode.steps < PROTOCOL.max_steps:  # a regression fails, not hangs
        waypoints = planner.plan(episode.observe())
        assert len(waypoints) == 1
        step = np.subtract(waypoints[0], episode.position) / PROTOCOL.node_resolution
        assert np.abs(step).max() <= 2  # one edge of the 5x5 lattice window
        decision = planner.last_decision
        modes.add(decision["mode"])
        if decision["mode"] == "local":
            assert decision["target"] == decision["local_tour"][0]
            if decision["global_tour"]:  # the local path joins the global tour
                assert decision["local_tour"][-1] == decision["global_tour"][0]
        episode.move(waypoints[0])
    assert episode.complete, f"not complete after {episode.steps} steps"
    assert {"local", "global"} <= modes


def test_small_horizon_still_completes(maze):
    """With a one-region horizon the plan flips at region borders; the loop guard copes."""
    planner = make_planner("tare", horizon_radius=0)
    modes = []
    plan = planner.plan

    def logged(observation):
        waypoints = plan(observation)
        modes.append(planner.last_decision["mode"])
        return waypoints

    planner.plan = logged
    res = run_episode(maze, planner, PROTOCOL)
    assert res.complete, res.failure
    assert res.motion_violations == 0
    assert "kept" in modes  # the guard acted (without it this run loops to the step limit)


def test_nothing_left_to_explore_returns_empty():
    free = np.zeros((60, 60), dtype=bool)
    free[5:55, 5:55] = True
    ground_truth = GroundTruthMap(free=free, start_cell=(30, 30), cell_size=PROTOCOL.cell_size, name="room")
    belief = np.where(free, FREE, OCCUPIED).astype(np.uint8)  # everything known
    planner = make_planner("tare")
    planner.reset(ground_truth, PROTOCOL, 0)
    assert planner.plan(Observation(belief, (0.0, 0.0), (30, 30), None, 0)) == []


def test_rejects_bad_options():
    with pytest.raises(ValueError):
        TarePlanner(TareConfig(horizon_radius=-1))
    with pytest.raises(ValueError):
        TarePlanner(TareConfig(min_cover=0))
    with pytest.raises(ValueError):
        TarePlanner(TareConfig(cover_range=-1.0))
