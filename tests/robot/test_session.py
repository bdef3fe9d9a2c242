"""`pipeline.robot.ExplorationSession`: a planner on a live SLAM map (OccupancyGrid) and pose."""

from __future__ import annotations

import math

import numpy as np
import pytest
from conftest import two_rooms

from pipeline.robot import ExplorationSession, GridMessage
from pipeline.robot.closed_loop import grid_message, slam_map
from pipeline.robot.occupancy_grid import Canvas, read_grid
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN
from pipeline.world.simulator import Episode

PROTOCOL = Protocol()  # the maze benchmark's: 0.4 m cells, 4 m lattice


def occupancy_message(episode: Episode, rng=None) -> GridMessage:
    """The simulator's belief as a SLAM map: 4 x finer cells, occupancy probabilities (not three
    values), cropped to the known area (so it grows and its origin moves as the robot explores)."""
    return grid_message(slam_map(episode, episode.protocol.cell_size / 4, rng or np.random.default_rng(0)))


def test_a_cell_is_free_only_where_every_finer_cell_is_and_occupied_where_any_is():
    canvas = Canvas(cell_size=0.4, step_cells=10, anchor=(0.2, 0.2))
    canvas.cover((0.0, 0.0, 0.8, 0.4))
    values = np.array(
        [[0, 0, 0, 0, 0, 0, 0, 0], [0, 0, 0, 0, 0, -1, 0, 0], [0, 0, 0, 0, 0, 0, 0, 90], [0, 0, 0, 0, 0, 0, 0, 0]]
    )  # 0.1 m cells: two 0.4 m cells side by side
    grid = read_grid(GridMessage(values.reshape(-1).tolist(), 8, 4, 0.1, 0.0, 0.0))
    canvas.paint(grid)
    first, second = canvas.to_cell(0.2, 0.2), canvas.to_cell(0.6, 0.2)
    assert canvas.belief[first[1], first[0]] == FREE
    assert canvas.belief[second[1], second[0]] == OCCUPIED  # one occupied fine cell is enough
    values[2, 7] = 30  # neither free nor occupied: the cell is unknown, not free
    canvas.paint(read_grid(GridMessage(values.reshape(-1).tolist(), 8, 4, 0.1, 0.0, 0.0)))
    assert canvas.belief[second[1], second[0]] == UNKNOWN


def test_a_growing_map_whose_origin_moves_keeps_what_was_seen_and_the_lattice_in_place():
    canvas = Canvas(cell_size=0.4, step_cells=10, anchor=(1.0, 1.0))
    canvas.cover((1.0, 1.0, 1.0, 1.0), margin_m=4.0)
    canvas.paint(read_grid(GridMessage([0] * 25, 5, 5, 0.4, 0.0, 0.0)))
    seen = canvas.to_cell(0.5, 0.5)
    node = canvas.to_map((4.0, 0.0))
    grew = canvas.cover((-20.0, -20.0, 2.0, 2.0))
    canvas.paint(read_grid(GridMessage([-1] * 4, 2, 2, 0.4, -20.0, -20.0)))  # says nothing about the first cells
    assert grew and canvas.belief[canvas.to_cell(0.5, 0.5)[::-1]] == FREE
    assert canvas.to_map((4.0, 0.0)) == pytest.approx(node)
    assert canvas.to_cell(0.5, 0.5) != seen  # the cells moved in the grown grid, the map-frame point did not


@pytest.mark.parametrize("planner", ["greedy_utility", "guide_tsp", "guide"])
def test_the_session_explores_a_maze_in_closed_loop(small_maze, planner):
    """The simulator plays robot and SLAM: finer cropped maps with probabilities, a noisy pose
    (0.1 m, any heading); the session's waypoints are driven on the simulator's lattice (the first
    pose anchors the session's at the simulator's start); exploration completes."""
    rng = np.random.default_rng(1)
    episode = Episode(small_maze, PROTOCOL)
    session = ExplorationSession(planner, PROTOCOL, planner_options={"candidates": 2} if planner == "guide" else None)
    session.update_pose(*episode.position)  # the lattice is anchored at the first pose: the simulator's start
    checked = []  # predicted nodes checked so far: kept over the planner's resets on new frames
    for _ in range(300):
        assert session.update_map(occupancy_message(episode, rng=rng))
        x, y = episode.position
        assert session.update_pose(x + rng.normal(0, 0.1), y + rng.normal(0, 0.1), rng.uniform(-math.pi, math.pi))
        plan = session.plan(force=True)
        if plan.done:
            break
        assert plan.waypoints and plan.decision_ms > 0 and plan.target is not None
        trust = session.state.prediction_trust
        if trust is not None:
            checked.append(trust["right"] + trust["wrong"])
            assert 0.0 <= trust["trust"] <= 1.0
        episode.move(plan.waypoints[0])
    assert episode.completion_distance is not None, f"{planner}: {episode.explored_share:.2f} explored"
    assert session.state.maps_skipped == 0 and session.state.resets >= 2  # the map grew past its first frame
    if planner == "greedy_utility":
        assert session.state.prediction_trust is None
    else:
        assert checked[-1] > 0 and checked == sorted(checked)


def test_plans_are_kept_until_a_waypoint_is_reached_the_map_changes_or_time_passes(small_maze):
    now = [0.0]
    episode = Episode(small_maze, PROTOCOL)
    session = ExplorationSession("greedy_utility", PROTOCOL, replan_after_s=10.0, clock=lambda: now[0])
    assert session.plan().reason == "waiting for a map and a pose"
    session.update_map(occupancy_message(episode))
    session.update_pose(*episode.position)
    first = session.plan()
    assert first.replanned and first.waypoints
    again = session.plan()
    assert not again.replanned and again.waypoints == first.waypoints and again.reason == "kept"
    now[0] = 11.0
    assert session.plan().reason == "timeout"
    session.update_pose(*first.waypoints[0])
    assert session.plan().reason == "waypoint reached"


def test_a_failed_goal_is_avoided(small_maze):
    episode = Episode(small_maze, PROTOCOL)
    session = ExplorationSession("greedy_utility", PROTOCOL)
    session.update_map(occupancy_message(episode))
    session.update_pose(*episode.position)
    first = session.plan()
    session.goal_failed(*first.waypoints[0])
    second = session.plan()
    assert second.replanned and first.waypoints[0] not in second.waypoints
    assert session.state.failed_goals == [first.waypoints[0]]


BAD_MAPS = [
    ("an empty map", GridMessage([], 0, 0, 0.05)),
    ("data of the wrong length", GridMessage([0] * 5, 3, 3, 0.05)),
    ("values outside -1..100", GridMessage([0, 101, 0, 0], 2, 2, 0.05)),
    ("a NaN resolution", GridMessage([0] * 4, 2, 2, float("nan"))),
    ("a zero resolution", GridMessage([0] * 4, 2, 2, 0.0)),
    ("an infinite origin", GridMessage([0] * 4, 2, 2, 0.05, float("inf"), 0.0)),
    ("not a message", object()),
]


@pytest.mark.parametrize("what,message", BAD_MAPS, ids=[w for w, _ in BAD_MAPS])
def test_a_bad_map_is_logged_and_skipped_and_the_next_good_one_plans(what, message, small_maze, caplog):
    episode = Episode(small_maze, PROTOCOL)
    session = ExplorationSession("greedy_utility", PROTOCOL)
    session.update_pose(*episode.position)
    assert session.update_map(message) is False
    assert session.state.maps_skipped == 1 and "map skipped" in caplog.text
    assert session.update_map(occupancy_message(episode))
    assert session.plan().waypoints


@pytest.mark.parametrize("pose", [(float("nan"), 0.0, 0.0), (0.0, float("inf"), 0.0), ("a", 0.0, 0.0), (1e6, 1e6, 0.0)])
def test_a_bad_pose_is_logged_and_skipped(pose, small_maze):
    episode = Episode(small_maze, PROTOCOL)
    session = ExplorationSession("greedy_utility", PROTOCOL)
    session.update_map(occupancy_message(episode))
    session.update_pose(*episode.position)
    assert session.update_pose(*pose) is False
    assert session.state.poses_skipped == 1
    assert session.plan().waypoints  # planned from the last good pose


def test_protocols_by_name_and_a_clear_error_for_others():
    assert ExplorationSession("greedy_utility", "maze").protocol == Protocol()
    assert ExplorationSession("greedy_utility", "real_robot").protocol.node_resolution == 1.0
    with pytest.raises(ValueError, match="protocol must be a Protocol or one of maze, real_robot"):
        ExplorationSession("greedy_utility", "mars")
    with pytest.raises(ValueError, match="whole number of cells"):
        ExplorationSession("greedy_utility", Protocol(cell_size=0.3, node_resolution=1.0, sensor_range=10.0))


def fuzzed_message(rng: np.random.Generator):
    """A message that may be anything an OccupancyGrid topic could carry, good or bad."""
    kind = rng.integers(0, 8)
    if kind == 0:
        return object()
    width, height = int(rng.integers(-2, 40)), int(rng.integers(-2, 40))
    resolution = float(rng.choice([0.05, 0.1, 0.4, 1.0, 0.0, -0.05, np.nan, np.inf, 1e-9, 500.0]))
    origin = [float(rng.choice([0.0, -3.0, 7.5, 1e7, -1e9, np.nan, np.inf])) for _ in range(2)]
    count = max(0, width * height) + int(rng.choice([0, 0, 0, 1, -1]))
    values = rng.integers(-3, 105, max(0, count)) if kind < 6 else rng.choice([-1, 0, 100], max(0, count))
    data = values.tolist() if kind != 7 else ["x"] * max(0, count)
    return GridMessage(data, width, height, resolution, origin[0], origin[1])


def fuzzed_pose(rng: np.random.Generator):
    return tuple(rng.choice([0.0, 1.3, -2.0, 40.0, 1e9, -1e9, np.nan, np.inf, -np.inf]) for _ in range(3))


@pytest.mark.parametrize("planner", ["greedy_utility", "guide"])
def test_a_thousand_fuzzed_messages_and_poses_end_no_session(planner, small_maze, caplog):
    """Every fuzzed message and pose is taken or skipped, never a traceback, and the next good
    message and pose give a valid plan."""
    rng = np.random.default_rng(7)
    episode = Episode(small_maze, PROTOCOL)
    good = occupancy_message(episode)
    session = ExplorationSession(planner, PROTOCOL, planner_options={"candidates": 1} if planner == "guide" else None)
    fuzzed = 1000 if planner == "greedy_utility" else 200
    for _ in range(fuzzed):
        session.update_map(fuzzed_message(rng))
        session.update_pose(*fuzzed_pose(rng))
        session.plan()
        session.update_map(good)
        session.update_pose(*episode.position)
        plan = session.plan(force=True)
        assert plan.waypoints or plan.done, plan.reason
    assert session.state.maps_skipped > fuzzed // 2 and session.state.poses_skipped > fuzzed // 4


def diagonal_door(gap_m: float = 0.45, offset: int = 3) -> np.ndarray:
    """An 8 x 8 m SLAM map at 0.05 m: a 3-pixel diagonal wall with a `gap_m` door that the
    protocol's conservative 0.2 m cells close (each of them holds a pixel of the door's frames)."""
    values = np.zeros((160, 160), np.int8)
    values[:, :2] = values[:, -2:] = values[:2, :] = values[-2:, :] = 100
    rows, cols = np.mgrid[0:160, 0:160]
    along = (rows + cols) / np.sqrt(2) * 0.05
    door = (along > 3.0) & (along < 3.0 + gap_m)
    values[(np.abs(rows - cols - offset) <= 1) & ~door] = 100
    return values


@pytest.mark.parametrize("gap_m, opens", [(0.45, True), (0.3, False)])
def test_a_door_the_robot_fits_through_stays_open_on_the_protocols_cells(gap_m, opens):
    from pipeline.world.reachability import reachable_from

    values = diagonal_door(gap_m)
    message = GridMessage(values.reshape(-1).tolist(), 160, 160, 0.05, 0.0, 0.0)
    reached = []
    for radius in (0.0, 0.2):
        canvas = Canvas(0.2, 5, (1.5, 6.5), robot_radius_m=radius)
        canvas.cover((0.0, 0.0, 8.0, 8.0))
        canvas.paint(read_grid(message))
        reach = reachable_from(canvas.belief == FREE, canvas.to_cell(1.5, 6.5))
        reached.append(bool(reach[canvas.to_cell(6.5, 1.5)[::-1]]))
    assert reached == [False, opens]  # conservative cells close it; the radius opens it when the robot fits


def test_done_means_no_frontier_the_robot_can_reach_is_left():
    """A room behind a door no lattice edge crosses: the session is not done while it is unseen."""
    world = two_rooms()
    session = ExplorationSession("nearest_frontier", "real_robot")
    belief = np.where(world.free, 0, 100).astype(np.int8)
    belief[:, 28:] = -1  # the right room unknown, the door's cells known free
    session.update_map(GridMessage(belief.reshape(-1).tolist(), 120, 60, 0.2, 0.0, 0.0))
    col, row = world.start_cell
    session.update_pose((col + 0.5) * 0.2, (row + 0.5) * 0.2, 0.0)
    plan = session.plan()
    assert not plan.done and plan.waypoints
    known = np.where(world.free, 0, 100).astype(np.int8)
    session.update_map(GridMessage(known.reshape(-1).tolist(), 120, 60, 0.2, 0.0, 0.0))
    assert session.plan(force=True).done  # everything seen: done


def test_save_map_writes_the_belief_as_a_ros_map(small_maze, tmp_path):
    from pipeline.robot.closed_loop import ClosedLoopConfig, run_closed_loop
    from pipeline.world.maps import read_ros_grid
    from pipeline.world.sensor import FREE

    session = ExplorationSession("greedy_utility", Protocol())
    with pytest.raises(ValueError, match="no map to save yet"):
        session.save_map(tmp_path / "early.yaml")
    run_closed_loop(small_maze, session, ClosedLoopConfig(max_decisions=5, cdr=False))
    path = session.save_map(tmp_path / "runs")
    assert path == tmp_path / "runs" / "map.yaml" and (tmp_path / "runs" / "map.pgm").is_file()
    grid = read_ros_grid(path)
    assert grid.resolution == pytest.approx(0.4) and grid.origin == pytest.approx(session.canvas.origin)
    assert np.array_equal(grid.free, session.canvas.belief == FREE)
    assert grid.meta["start"] == pytest.approx(list(session.canvas.anchor))
