"""The whole building: planners pass doors the lattice misses and stop only when nothing is left."""

from dataclasses import replace

import numpy as np
import pytest
from conftest import two_rooms

from pipeline.planners import make_planner
from pipeline.planners.whole_building import WholeBuilding
from pipeline.planners.wrapper import innermost, layer
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import PAPER_REAL_ROBOT, Protocol
from pipeline.world.simulator import STOPPED, replay, run_episode

UNTIL_DONE = replace(PAPER_REAL_ROBOT, done_unknown_cells=0, max_steps=400)  # runs until the planner says done


def thick_wall() -> GroundTruthMap:
    """Two rooms joined by a passage 2 cells wide through a wall 3.6 m thick, off every lattice row:
    no lattice edge (two lattice steps at most) spans it, and no door node sees both ends."""
    free = np.ones((60, 140), bool)
    free[0, :] = free[-1, :] = free[:, 0] = free[:, -1] = False
    free[:, 40:58] = False
    free[29:31, 40:58] = True
    return GroundTruthMap(free=free, start_cell=(12, 12), cell_size=0.2, name="thick_wall")


@pytest.mark.parametrize("name", ["greedy_utility", "nearest_frontier"])
def test_the_lattice_alone_stops_early_and_the_door_graph_explores_it_all(name):
    world = two_rooms()
    stranded = run_episode(world, make_planner(name), replace(UNTIL_DONE, door_graph=False))
    assert stranded.failure == STOPPED and stranded.early_stop and stranded.reachable_share < 0.7
    result = run_episode(world, make_planner(name), UNTIL_DONE)
    assert not result.early_stop and result.reachable_share >= 0.97
    assert result.fallbacks == 0  # the door nodes were enough: the planner's own rule did it all
    check = replay(world, result.trajectory, UNTIL_DONE)
    assert check.motion_violations == 0 and check.distance_m == pytest.approx(result.distance_m)
    off_lattice = [p for p in result.trajectory if any(abs(v - round(v)) > 1e-6 for v in p)]
    assert off_lattice  # it drove through a door node


def test_the_fallback_takes_the_robot_where_no_edge_leads_and_counts_itself():
    world = thick_wall()
    planner = make_planner("greedy_utility")
    result = run_episode(world, planner, UNTIL_DONE)
    assert (result.complete or result.failure == STOPPED) and not result.early_stop
    assert result.reachable_share >= 0.97 and result.fallbacks >= 1
    rows = result.step_rows()
    assert sum(1 for row in rows if row["fallback"]) >= 1 and rows[0]["fallback"] is False
    assert replay(world, result.trajectory, UNTIL_DONE).motion_violations == 0


def test_at_the_maze_scale_the_wrapper_changes_nothing(small_maze):
    protocol = Protocol(max_steps=60)
    wrapped = make_planner("greedy_utility")
    assert isinstance(wrapped, WholeBuilding)
    plain = innermost(make_planner("greedy_utility"))
    a, b = run_episode(small_maze, wrapped, protocol), run_episode(small_maze, plain, protocol)
    assert a.trajectory == b.trajectory and a.fallbacks == 0 and not any(a.waypoint_fallback)


def test_oracles_are_not_wrapped():
    assert not isinstance(make_planner("optimal"), WholeBuilding)


def test_a_robot_standing_on_a_frontier_cell_goes_on_to_the_next_not_done():
    """A session's robot stands near its cell, not on it, and may scan a frontier cell without
    clearing it: standing there is a visit, the cell is given up, and the next frontier is the target."""
    from pipeline.planners.whole_building import MAX_TRIES
    from pipeline.world.planner import Observation
    from pipeline.world.protocol import PAPER_REAL_ROBOT
    from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN

    belief = np.full((30, 40), OCCUPIED, np.uint8)
    belief[5:25, 5:35] = FREE
    belief[13:16, 5] = UNKNOWN  # beside the robot's own cell, (6, 14), which is so a frontier cell
    belief[12:17, 0:5] = UNKNOWN  # behind it, 25 unknown cells
    belief[5:25, 35:40] = UNKNOWN  # far away: a second unknown region
    planner = make_planner("nearest_frontier")
    from pipeline.world.maps import MapFrame

    planner.reset(MapFrame(belief.shape, 0.2, (6, 14)), PAPER_REAL_ROBOT, 0)
    innermost(planner).plan = lambda observation: []  # its own rule finds nothing
    waypoints = planner.plan(Observation(belief=belief, position=(0.0, 0.0), cell=(6, 14), changed=None, step=0))
    assert waypoints and planner.decision_kind == "fallback"  # before: its own cell was the nearest target, so "done"
    assert (0.0, 0.0) not in waypoints
    assert layer(planner, WholeBuilding).tries[14, 6] == MAX_TRIES


def test_a_node_under_the_threshold_is_no_target_when_only_a_grazed_cell_is_left():
    """Greedy's own rule takes any node that sees a frontier cell when none sees `min_utility`;
    under the door-aware graph such a node is not followed, and with no open frontier left the
    planner is done (a robot stopping near such nodes could tour them without end)."""
    from pipeline.world.maps import MapFrame
    from pipeline.world.planner import Observation
    from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN

    belief = np.full((30, 60), OCCUPIED, np.uint8)
    belief[5:25, 5:55] = FREE
    belief[4, 49] = belief[4, 51] = UNKNOWN  # two single unknown cells in the wall: one frontier cell between
    observation = Observation(belief=belief, position=(0.0, 0.0), cell=(10, 15), changed=None, step=0)
    plain = innermost(make_planner("greedy_utility"))
    plain.reset(MapFrame(belief.shape, 0.2, (10, 15)), UNTIL_DONE, 0)
    assert plain.plan(observation)  # its own rule heads for a node that sees the one frontier cell
    assert not np.any((plain.graph.utility >= plain.min_utility) & ~plain.visited)
    wrapped = make_planner("greedy_utility")
    wrapped.reset(MapFrame(belief.shape, 0.2, (10, 15)), UNTIL_DONE, 0)
    assert wrapped.plan(observation) == [] and wrapped.decision_kind == "done"
