"""The robot path in closed loop without ROS: SLAM maps through CDR, a noisy pose, a robot that
drives along free cells and stops near its goal, goals that fail; exploration completes."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import two_rooms

from pipeline.robot import ExplorationSession
from pipeline.robot.closed_loop import ClosedLoopConfig, as_ros_message, edge_walls, free_path, run_closed_loop
from pipeline.robot.occupancy_grid import read_grid
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN


@pytest.mark.parametrize("planner", ["greedy_utility", "guide_tsp", "guide"])
def test_exploration_completes_through_cdr_maps_noisy_poses_and_failing_goals(planner, small_maze):
    options = {"candidates": 2} if planner == "guide" else None
    session = ExplorationSession(planner, Protocol(), planner_options=options)
    result = run_closed_loop(small_maze, session, ClosedLoopConfig(fail_every=10), seed=3)
    assert result.complete, result
    assert result.maps_skipped == 0 and result.failed_goals >= 1
    assert session.state.maps_used == result.decisions
    assert 50.0 < result.distance_m < 600.0


@pytest.mark.parametrize("planner", ["greedy_utility", "guide"])
def test_the_session_explores_the_room_behind_a_door_the_lattice_misses(planner):
    """Real-robot protocol: the session says done only when all it can reach is seen."""
    session = ExplorationSession(
        planner, "real_robot", planner_options={"candidates": 2} if planner == "guide" else None
    )
    result = run_closed_loop(two_rooms(), session, ClosedLoopConfig(fail_every=0, max_decisions=400), seed=1)
    assert result.done and not result.early_stop and result.reachable_share >= 0.97, result


def test_a_plan_whose_free_space_runs_to_its_border_is_done_when_seen():
    """The ground truth ends in a wall: two rooms with no outer wall (free to the grid's edge), at
    the real-robot protocol, say done once seen, as in the simulator."""
    free = two_rooms().free.copy()
    free[0, :] = free[-1, :] = free[:, 0] = free[:, -1] = True
    world = GroundTruthMap(free=free, start_cell=(12, 32), cell_size=0.2, name="no_outer_wall")
    session = ExplorationSession("greedy_utility", "real_robot")
    result = run_closed_loop(world, session, ClosedLoopConfig(fail_every=0, max_decisions=400), seed=1)
    assert result.done and not result.early_stop and result.reachable_share >= 0.97, result


def test_the_edge_of_the_ground_truth_reads_as_a_wall_beside_free_cells_only():
    grid = np.full((3, 4), UNKNOWN, np.uint8)
    grid[0, 0] = FREE  # a corner cell: its three outside neighbours and their two neighbours
    grid[1, 3] = OCCUPIED  # an occupied edge cell: nothing outside it
    edged = edge_walls(grid)
    assert edged.shape == (5, 6) and (edged[1:-1, 1:-1] == grid).all()
    walls = {(int(r), int(c)) for r, c in zip(*np.nonzero(edged == OCCUPIED))} - {(2, 4)}
    assert walls == {(0, 0), (0, 1), (0, 2), (1, 0), (2, 0)}


def test_a_map_survives_cdr_with_rosbags_types():
    fields = {
        "data": np.array([0, -1, 100, 42], np.int8),
        "width": 2,
        "height": 2,
        "resolution": 0.05,
        "x": 1.5,
        "y": -2.0,
    }
    msg = as_ros_message(fields, 12.25)
    assert type(msg).__msgtype__ == "nav_msgs/msg/OccupancyGrid" and msg.header.frame_id == "map"
    grid = read_grid(msg)
    assert grid.values.tolist() == [[0, -1], [100, 42]] and grid.origin == (1.5, -2.0)
    assert grid.resolution == pytest.approx(0.05)


def test_the_robot_drives_only_through_known_free_cells():
    free = np.ones((5, 5), bool)
    free[1:4, 2] = False  # a wall with gaps at the top and bottom rows
    path = free_path(free, (0, 2), (4, 2))
    assert path[0] == (0, 2) and path[-1] == (4, 2)
    assert all(free[row, col] for col, row in path)
    free[:, 2] = False
    assert free_path(free, (0, 2), (4, 2)) is None
