"""Planners decide from what a robot has: every planner that does not see the ground truth is reset
from the map's frame (extent, cell size, start) and holds no ground-truth map; only oracles get one."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.planners import make_planner, planner_config, planner_names
from pipeline.world.maps import GroundTruthMap, MapFrame, map_frame
from pipeline.world.planner import Planner, reset_planner
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import Episode, run_episode

PROTOCOL = Protocol(max_steps=6)
HEAVY = {"oracle_lookahead", "sampled_lookahead"}  # rollouts on every decision: covered by their own tests


def holds_ground_truth(obj, seen=None, depth=0) -> bool:
    """Whether `obj` reaches a GroundTruthMap through its attributes, containers or wrapped planners."""
    seen = set() if seen is None else seen
    if id(obj) in seen or depth > 6:
        return False
    seen.add(id(obj))
    if isinstance(obj, GroundTruthMap):
        return True
    if isinstance(obj, dict):
        return any(holds_ground_truth(v, seen, depth + 1) for v in obj.values())
    if isinstance(obj, (list, tuple, set)):
        return any(holds_ground_truth(v, seen, depth + 1) for v in obj)
    if hasattr(obj, "__dict__") and not isinstance(obj, type) and type(obj).__module__.startswith("pipeline"):
        return any(holds_ground_truth(v, seen, depth + 1) for v in vars(obj).values())
    return False


class Spy(Planner):
    def __init__(self, oracle: bool):
        self.uses_ground_truth, self.given = oracle, None

    def reset(self, frame, protocol, seed):
        self.given = frame

    def plan(self, observation):
        return []


def test_the_frame_is_the_maps_extent_cell_size_and_start_only(small_maze):
    frame = small_maze.frame
    assert frame == MapFrame(small_maze.shape, small_maze.cell_size, small_maze.start_cell, small_maze.name)
    assert not hasattr(frame, "free") and map_frame(frame) is frame and map_frame(small_maze) == frame


def test_the_simulator_hands_the_ground_truth_to_oracles_only(small_maze):
    for oracle in (False, True):
        spy = Spy(oracle)
        run_episode(small_maze, spy, PROTOCOL)
        assert isinstance(spy.given, GroundTruthMap if oracle else MapFrame)
        reset_planner(spy, small_maze, PROTOCOL, 0)
        assert isinstance(spy.given, GroundTruthMap if oracle else MapFrame)


@pytest.mark.parametrize(
    "name", [n for n in planner_names() if not planner_config(n).uses_ground_truth and n not in HEAVY]
)
def test_a_planner_that_does_not_see_the_ground_truth_never_holds_it(name, small_maze):
    planner = make_planner(name)
    result = run_episode(small_maze, planner, PROTOCOL, seed=0)
    assert len(result.trajectory) > 1
    assert not holds_ground_truth(planner)


def test_an_oracle_does_hold_it(small_maze):
    planner = make_planner("expert")
    run_episode(small_maze, planner, PROTOCOL, seed=0)
    assert holds_ground_truth(planner)  # the check above can find one


def test_a_frame_alone_runs_a_learned_planner(small_maze):
    planner = make_planner("guide", candidates=2, num_inference_steps=2)
    planner.reset(small_maze.frame, Protocol(), 0)
    waypoints = planner.plan(Episode(small_maze, Protocol()).observe())
    assert waypoints and np.isfinite(np.asarray(waypoints)).all()
