"""Oracle bounds: the true-gain gate, the oracle gate and oracle tail planners, on a small maze."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.models.sliver_gate import SliverGate, TrueGain
from pipeline.planners import make_planner, planner_config
from pipeline.planners.references.oracle_bounds import TrueGainGate
from pipeline.planners.wrapper import innermost
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, UNKNOWN
from pipeline.world.simulator import Episode, run_episode


def test_true_gain_counts_the_free_cells_a_scan_would_add(small_maze):
    protocol = Protocol()
    gain = TrueGain(small_maze, protocol)
    cells = np.argwhere(small_maze.free)[[0, 200]][:, ::-1]  # two free cells, as (col, row)
    unknown = np.full(small_maze.free.shape, UNKNOWN, dtype=np.uint8)
    everything_free = np.where(small_maze.free, FREE, UNKNOWN).astype(np.uint8)
    fresh = gain.gains(unknown, cells)
    assert np.all(fresh > 0)
    for (col, row), count in zip(cells, fresh):  # on an unknown map: every free cell its scan reaches
        assert count == gain.lidar.scan((int(col), int(row))).free.size
    assert np.all(gain.gains(everything_free, cells) == 0)  # on a known map: nothing left to reveal


def test_true_gain_gate_passes_by_gain_and_vetoes_only_what_the_learned_gate_passes(small_maze):
    protocol = Protocol()
    gain = TrueGain(small_maze, protocol)
    belief = Episode(small_maze, protocol).observe().belief
    cells = np.argwhere(small_maze.free)[::97][:, ::-1]
    gains = gain.gains(belief, cells)
    threshold = int(np.median(gains)) + 1
    assert 0 < (gains >= threshold).sum() < len(cells)
    oracle = TrueGainGate(gain, threshold)
    assert np.array_equal(oracle.passes(belief, cells, protocol.sensor_range_cells), gains >= threshold)
    never = SliverGate.logistic((0.0, 0.0, 0.0), -50.0)
    assert not TrueGainGate(gain, threshold, never).passes(belief, cells, protocol.sensor_range_cells).any()


def test_oracle_gate_replaces_the_base_planners_gate_and_explores(small_maze):
    planner = make_planner("oracle_gate", base="greedy_utility", min_gain=20)
    assert planner_config("oracle_gate").uses_ground_truth
    result = run_episode(small_maze, planner, Protocol(), 0)
    assert isinstance(innermost(planner.base).gate, TrueGainGate) and innermost(planner.base).gate.learned is None
    assert result.complete and result.motion_violations == 0
    veto = make_planner("oracle_gate", veto=True)
    veto.reset(small_maze, Protocol(), 0)
    assert isinstance(innermost(veto.base).gate.learned, SliverGate)  # the learned gate stays, the truth vetoes


def test_oracle_tail_hands_over_to_the_expert_at_the_threshold(small_maze):
    protocol = Protocol()
    free = int(small_maze.free.sum())
    never = make_planner("oracle_tail", handover_cells=0)
    at_once = make_planner("oracle_tail", handover_cells=free)
    plain = run_episode(small_maze, make_planner("greedy_utility"), protocol, 0)
    assert run_episode(small_maze, never, protocol, 0).distance_m == pytest.approx(plain.distance_m)
    assert not never.handed_over  # complete (<= 250 cells unknown) before 0 were left
    expert = run_episode(small_maze, make_planner("expert"), protocol, 0)
    tail = run_episode(small_maze, at_once, protocol, 0)
    assert at_once.handed_over and tail.complete and tail.motion_violations == 0
    assert tail.distance_m == pytest.approx(expert.distance_m)  # handed over at the first decision


def test_oracle_lookahead_with_one_candidate_is_gated_greedy_and_with_three_is_shorter(small_maze):
    protocol = Protocol()
    assert planner_config("oracle_lookahead").uses_ground_truth
    gated = run_episode(small_maze, make_planner("greedy_utility", sliver_gate=True), protocol, 0)
    one = run_episode(small_maze, make_planner("oracle_lookahead", k=1), protocol, 0)
    assert one.trajectory == gated.trajectory
    three = run_episode(small_maze, make_planner("oracle_lookahead", k=3), protocol, 0)
    assert three.complete and three.motion_violations == 0
    assert three.distance_m < gated.distance_m  # it simulates its options on the truth
