"""Tests of the NBVP planner (pipeline/planners/nbvp.py) on a small hand-made maze."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.lattice.graph import NODE_FREE
from pipeline.planners import make_planner, planner_names
from pipeline.planners.baselines.nbvp import NBVPConfig, NBVPPlanner, view_gains
from pipeline.planners.wrapper import innermost
from pipeline.world.geometry import ray_end_offsets, walk_offsets
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import DEFAULT_ANGLES, FREE, OCCUPIED, UNKNOWN, Belief, scan
from pipeline.world.simulator import Episode, replay, run_episode

PROTOCOL = Protocol()


def small_maze() -> GroundTruthMap:
    """48 m x 32 m: three rooms joined by doors, walls two cells thick, start at cell (10, 10).

    Doors are 13 cells wide and centred on a lattice row/column (lattice step = 10 cells).
    """
    free = np.zeros((80, 120), dtype=bool)
    free[2:-2, 2:-2] = True
    free[:, 39:41] = False  # wall between room A (left) and the rest
    free[24:37, 39:41] = True  # door around row 30
    free[:, 79:81] = False  # wall between the middle room and the right rooms
    free[54:67, 79:81] = True  # door around row 60
    free[39:41, 80:] = False  # the right side split into two rooms
    free[39:41, 94:107] = True  # door around column 100
    free[10:30, 55:60] = False  # a pillar in the middle room
    return GroundTruthMap(free=free, start_cell=(10, 10), cell_size=PROTOCOL.cell_size, name="small")


@pytest.fixture(scope="module")
def maze() -> GroundTruthMap:
    return small_maze()


@pytest.fixture(scope="module")
def result(maze):
    return run_episode(maze, make_planner("nbvp"), PROTOCOL, seed=3)


def test_registered_with_a_description():
    assert "nbvp" in planner_names()
    planner = make_planner("nbvp")
    assert isinstance(innermost(planner), NBVPPlanner)  # inside the whole building's wrapper
    assert planner.name == "nbvp" and planner.description


def test_completes_without_motion_violations(maze, result):
    assert result.complete, result.failure
    assert result.failure == ""
    assert result.motion_violations == 0
    assert result.steps < PROTOCOL.max_steps
    # The trajectory replays through a fresh referee to the same distance.
    again = replay(maze, result.trajectory, PROTOCOL)
    assert again.complete and again.motion_violations == 0
    assert again.distance_m == pytest.approx(result.distance_m)


def test_same_seed_same_trajectory(maze, result):
    again = run_episode(maze, make_planner("nbvp"), PROTOCOL, seed=3)
    assert again.trajectory == result.trajectory
    assert again.distance_m == result.distance_m


def test_gain_zero_in_known_area_and_positive_facing_unknown():
    belief = np.full((60, 60), OCCUPIED, dtype=np.uint8)
    belief[1:-1, 1:-1] = FREE  # a closed, fully known room
    assert view_gains(belief, np.array([[30, 30], [5, 5]]), PROTOCOL.sensor_range_cells).tolist() == [0, 0]
    # Open a unknown band on the right: a node facing it sees unknown cells.
    belief[1:-1, 40:-1] = UNKNOWN
    gains = view_gains(belief, np.array([[30, 30], [5, 5]]), PROTOCOL.sensor_range_cells)
    assert gains[0] > 0
    # A node behind a known wall does not see the unknown band.
    belief[1:-1, 20] = OCCUPIED
    gains = view_gains(belief, np.array([[30, 30], [10, 30]]), PROTOCOL.sensor_range_cells)
    assert gains[0] > 0 and gains[1] == 0


def reference_gain(belief: np.ndarray, cell: tuple[int, int], range_cells: float, ray_stride: int) -> int:
    """Plain per-ray loop: unknown cells seen through free/unknown cells, each counted once."""
    rows, cols = belief.shape
    seen = set()
    for ex, ey in ray_end_offsets(cell[0], cell[1], range_cells, DEFAULT_ANGLES[::ray_stride]):
        for ox, oy in walk_offsets(int(ex), int(ey))[:-1]:  # the end cell is never revealed
            x, y = cell[0] + int(ox), cell[1] + int(oy)
            if not (0 <= x < cols and 0 <= y < rows) or belief[y, x] == OCCUPIED:
                break
            if belief[y, x] == UNKNOWN:
                seen.add((x, y))
    return len(seen)


@pytest.mark.parametrize("ray_stride", [3, 8])
def test_gain_matches_a_plain_loop(ray_stride):
    rng = np.random.default_rng(1)
    belief = rng.choice([FREE, UNKNOWN, OCCUPIED], p=[0.6, 0.33, 0.07], size=(45, 70)).astype(np.uint8)
    cells = np.array([(0, 0), (35, 22), (69, 44), (5, 40), (60, 3)])
    belief[cells[:, 1], cells[:, 0]] = FREE  # origins are nodes the robot could stand on
    range_cells = 25.0
    gains = view_gains(belief, cells, range_cells, ray_stride)
    assert gains.tolist() == [reference_gain(belief, tuple(c), range_cells, ray_stride) for c in cells]
    assert (gains > 0).all()


@pytest.mark.parametrize("ray_stride", [1, 4])
def test_gain_is_zero_where_the_robot_has_sensed(maze, ray_stride):
    """The gain's ray fan is a subset of the lidar's rays: nothing is left to see there."""
    belief = Belief(maze.shape)
    for cell in [(10, 10), (30, 30), (60, 60)]:
        belief.apply(scan(maze.free, cell, PROTOCOL.sensor_range_cells))
    cells = np.array([(10, 10), (30, 30), (60, 60), (50, 30)])
    gains = view_gains(belief.grid, cells, PROTOCOL.sensor_range_cells, ray_stride)
    assert gains[:3].tolist() == [0, 0, 0]
    assert belief.grid[30, 50] == FREE and gains[3] > 0  # a sensed-free cell that faces unknown space


def test_tree_uses_valid_edges_and_first_edge_of_best_branch(maze):
    planner = make_planner("nbvp", tree_size=30)
    planner.reset(maze, PROTOCOL, seed=5)
    episode = Episode(maze, PROTOCOL)
    for _ in range(6):
        observation = episode.observe()
        waypoints = planner.plan(observation)
        graph = innermost(planner).graph
        tree = planner.last_decision["tree"]
        parent = planner.last_decision["parent"]
        robot = graph.nearest_node(observation.position)
        assert tree[0] == robot
        assert len(set(tree.tolist())) == len(tree)  # no lattice node twice
        assert len(tree) <= 30
        assert (graph.node_state[tree] == NODE_FREE).all()
        valid = {tuple(sorted(e)) for e in graph.edges.tolist()}
        for k in range(1, len(tree)):
            assert parent[k] < k
            assert tuple(sorted((int(tree[parent[k]]), int(tree[k])))) in valid
        assert len(waypoints) == 1
        if planner.last_decision["mode"] == "nbv":
            k = planner.last_decision["best"]
            while parent[k] != 0:
                k = parent[k]
            assert waypoints[0] == tuple(graph.node_world[tree[k]])
        episode.move(waypoints[0])


def test_branch_values_follow_bircher():
    planner = NBVPPlanner(NBVPConfig(lam=0.5))
    gains = np.array([0, 10, 4, 6])
    parent = np.array([-1, 0, 1, 0])
    cost = np.array([0.0, 4.0, 8.0, 4.0])
    values = planner.branch_values(gains, parent, cost)
    e4, e8 = np.exp(-2.0), np.exp(-4.0)
    assert values == pytest.approx([0.0, 10 * e4, 10 * e4 + 4 * e8, 6 * e4])


def test_fallback_is_nearest_frontier(maze):
    """With an unreachable gain threshold every decision is the nearest-frontier step."""
    ours = run_episode(maze, make_planner("nbvp", gain_threshold=np.inf), PROTOCOL, seed=0)
    reference = run_episode(maze, make_planner("nearest_frontier"), PROTOCOL, seed=0)
    assert ours.complete and ours.trajectory == reference.trajectory


def test_rejects_bad_parameters():
    with pytest.raises(ValueError):
        NBVPPlanner(NBVPConfig(tree_size=1))
    with pytest.raises(ValueError):
        NBVPPlanner(NBVPConfig(lam=-1.0))
    with pytest.raises(ValueError):
        NBVPPlanner(NBVPConfig(ray_stride=0))
