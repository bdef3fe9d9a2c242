"""The whole building: planners pass doors the lattice misses and stop only when nothing is left."""

from dataclasses import replace

import numpy as np
import pytest
from conftest import two_rooms

from pipeline.planners import make_planner
from pipeline.planners.whole_building import WholeBuilding
from pipeline.planners.wrapper import innermost
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
