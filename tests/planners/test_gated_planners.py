"""Planners with the sliver gate: which have it by default, what it keeps, and that they still explore."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.planners import make_planner
from pipeline.protocol import Protocol
from pipeline.simulator import Episode, run_episode
from pipeline.sliver_gate import SliverGate, save_gate


@pytest.mark.parametrize(("name", "gated"), [("greedy_utility", False), ("nearest_frontier", False),
                                             ("guide_tsp", True), ("guide", True), ("guide_noregion", True),
                                             ("dare", False)])
def test_which_planners_gate_by_default(name, gated):
    assert (make_planner(name).gate is not None) == gated
    assert (make_planner(name, sliver_gate=not gated).gate is not None) == (not gated)  # the option overrides


def test_the_gate_keeps_a_subset_and_falls_back_when_it_passes_nothing(small_maze, tmp_path):
    protocol = Protocol()
    plain = make_planner("greedy_utility")
    gated = make_planner("greedy_utility", sliver_gate=True)
    nothing = make_planner("greedy_utility", sliver_gate=True, gate_file=str(save_gate(
        SliverGate(coef=(0.0, 0.0, 0.0), intercept=-50.0), tmp_path / "never.json")))
    observation = Episode(small_maze, protocol).observe()  # the first scan
    for planner in (plain, gated, nothing):
        planner.reset(small_maze, protocol, 0)
        planner.update_graph(observation)
    everything = plain.useful_nodes()
    kept = gated.useful_nodes()
    assert everything.size > 0 and kept.size > 0 and set(kept) <= set(everything)
    assert np.array_equal(nothing.useful_nodes(), everything)  # nothing passes: every useful node stays


@pytest.mark.parametrize("name", ["greedy_utility", "guide_tsp"])
def test_gated_planners_complete_the_maze(small_maze, name):
    result = run_episode(small_maze, make_planner(name, sliver_gate=True), Protocol(), 0)
    assert result.complete and result.motion_violations == 0
