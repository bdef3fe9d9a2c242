"""Planners with the sliver gate: which have it by default, what it keeps, and that they still explore."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.models.defaults import SHIPPED_GATE
from pipeline.models.sliver_gate import SliverGate, save_gate
from pipeline.planners import make_planner
from pipeline.planners.wrapper import innermost
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import Episode, run_episode


@pytest.mark.parametrize(
    ("name", "gated"),
    [
        ("greedy_utility", False),
        ("nearest_frontier", False),
        ("guide_tsp", True),
        ("guide", True),
        ("guide_noregion", True),
        ("dare", False),
    ],
)
def test_which_planners_gate_by_default(name, gated):
    assert (innermost(make_planner(name)).gate is not None) == gated
    assert (innermost(make_planner(name, sliver_gate=not gated)).gate is not None) == (
        not gated
    )  # the option overrides
    assert "sliver gate" in make_planner(name, sliver_gate=True).description  # run.json says which gate ran


def test_the_gate_keeps_a_subset_and_falls_back_when_it_passes_nothing(small_maze, tmp_path):
    protocol = Protocol()
    plain = make_planner("greedy_utility")
    gated = make_planner("greedy_utility", sliver_gate=True)
    nothing = make_planner(
        "greedy_utility",
        sliver_gate=True,
        gate_file=str(save_gate(SliverGate.logistic((0.0, 0.0, 0.0), -50.0), tmp_path / "never.json")),
    )
    observation = Episode(small_maze, protocol).observe()  # the first scan
    for planner in (plain, gated, nothing):
        planner.reset(small_maze, protocol, 0)
        innermost(planner).update_graph(observation)
    everything = innermost(plain).useful_nodes()
    kept = innermost(gated).useful_nodes()
    assert everything.size > 0 and kept.size > 0 and set(kept) <= set(everything)
    assert np.array_equal(innermost(nothing).useful_nodes(), everything)  # nothing passes: every useful node stays


@pytest.mark.parametrize("name", ["greedy_utility", "guide_tsp"])
def test_gated_planners_complete_the_maze(small_maze, name):
    result = run_episode(small_maze, make_planner(name, sliver_gate=True), Protocol(), 0)
    assert result.complete and result.motion_violations == 0


def test_the_gate_falls_back_when_every_node_it_passes_is_unreachable(small_maze, tmp_path):
    """A gate that passes only nodes the robot cannot reach must not leave it without a target
    (it did on an office-like map: the episode ended with reachable frontier left)."""
    protocol = Protocol()
    always = make_planner(
        "greedy_utility",
        sliver_gate=True,
        gate_file=str(save_gate(SliverGate.logistic((0.0, 0.0, 0.0), 50.0), tmp_path / "always.json")),
    )
    always.reset(small_maze, protocol, 0)
    innermost(always).update_graph(Episode(small_maze, protocol).observe())
    everything = innermost(always).useful_nodes()
    assert everything.size > 1
    dist = np.zeros(innermost(always).graph.node_count)
    dist[everything[0]] = np.inf  # a known-graph distance in which only one useful node is cut off
    innermost(always)._gated = None
    assert np.array_equal(innermost(always).useful_nodes(dist), everything[1:])  # the gate passes the reachable ones
    dist[everything] = np.inf  # now every node the gate passes is out of reach
    innermost(always)._gated = None
    assert np.array_equal(innermost(always).useful_nodes(dist), everything)  # so every useful node stays


def test_kept_gate_verdicts_match_the_gate_on_the_current_belief(generated_maze_dir):
    """Verdicts are kept per node until a belief change comes within the gate's reach; every kept
    one must be what the gate says on the belief of the moment, and some must be kept."""
    from pipeline.world.maps import load_map

    protocol = Protocol()
    checked = kept = 0
    for path in sorted(generated_maze_dir.glob("*.png")):
        planner = make_planner(
            "greedy_utility", sliver_gate=True, gate_file=str(SHIPPED_GATE)
        )  # no wrapper: plan is patched
        plan, judged_before = planner.plan, [np.zeros(0, dtype=bool)]

        def checked_plan(observation, planner=planner, plan=plan, judged_before=judged_before):
            nonlocal checked, kept
            waypoints = plan(observation)
            known = np.nonzero(innermost(planner)._gate_known)[0]
            fresh = innermost(planner).gate.passes(
                observation.belief, innermost(planner).graph.node_cells[known], protocol.sensor_range_cells
            )
            assert np.array_equal(innermost(planner)._gate_big[known], fresh)
            if judged_before[0].size == innermost(planner)._gate_known.size:
                kept += int((judged_before[0] & innermost(planner)._gate_known).sum())
            judged_before[0] = innermost(planner)._gate_known.copy()
            checked += known.size
            return waypoints

        planner.plan = checked_plan
        assert run_episode(load_map(path), planner, protocol, 0).complete
    assert checked > 0 and kept > 0


@pytest.mark.parametrize("lazy_utilities", [False, True])
@pytest.mark.parametrize("gate", ["fitted", "passes_nothing"])
def test_lazy_ranking_chooses_what_the_full_ranking_chooses(small_maze, tmp_path, gate, lazy_utilities):
    """Rollouts rank lazily (`_best_gated`, `_is_gated_target`): the gate down the ungated ranking,
    and on rollout copies utilities kept as bounds until they reach the top. At every decision of a
    gated-greedy episode they must give `ranked_targets`' first target and its targets, also when
    the gate passes nothing and every useful node stays a target."""
    protocol = Protocol()
    options = (
        {}
        if gate == "fitted"
        else {"gate_file": str(save_gate(SliverGate.logistic((0.0, 0.0, 0.0), -50.0), tmp_path / "never.json"))}
    )
    planner = make_planner("greedy_utility", sliver_gate=True, **options)
    lazy = make_planner("greedy_utility", sliver_gate=True, **options)  # judges only what the lazy rule asks for
    episode = Episode(small_maze, protocol)
    planner.reset(small_maze, protocol, 0)
    lazy.reset(small_maze, protocol, 0)
    innermost(lazy).graph.lazy_utilities = lazy_utilities
    decisions = bounded = 0
    while not episode.complete and episode.steps < 200:
        observation = episode.observe()
        pred, ranked = innermost(planner).ranked_targets(observation)
        innermost(lazy).update_graph(observation)
        dist, _ = innermost(lazy).graph.shortest_paths(innermost(lazy).robot)
        bounded += int(innermost(lazy).graph.stale.sum())
        if ranked.size == 0:
            assert innermost(lazy)._ranking_prefix(dist, 1).size == 0
            break
        assert innermost(lazy)._best_gated(dist) == int(ranked[0])
        targets = set(ranked.tolist())
        for node in range(innermost(planner).graph.node_count):
            assert innermost(lazy)._is_gated_target(node, dist) == (node in targets), node
        assert not (innermost(lazy).graph.stale & (innermost(lazy).graph.utility == 0)).any()
        episode.move(
            innermost(planner).waypoints_along(innermost(planner).graph.path_from_predecessors(pred, int(ranked[0])))[0]
        )
        decisions += 1
    assert decisions > 10 and episode.complete
    assert (bounded > 0) == lazy_utilities  # the lazy graph did keep bounds
