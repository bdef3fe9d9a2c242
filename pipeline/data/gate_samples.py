"""Training samples for the sliver gate: candidates of greedy episodes, labelled by the ground truth."""

from __future__ import annotations

import numpy as np

from pipeline.models.sliver_gate import TrueGain, gate_features
from pipeline.planners.baselines.frontier import GreedyUtilityPlanner
from pipeline.world.maps import GroundTruthMap
from pipeline.world.planner import Observation
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode


class _LabellingGreedy(GreedyUtilityPlanner):
    """`greedy_utility` (no gate) that records, at every decision, each reachable target's gate
    counts and the cells its scan would truly reveal (the label; it never steers)."""

    uses_ground_truth = True

    def __init__(self, wall_margin: int, range_cells: float):
        super().__init__()
        self.wall_margin, self.range_cells = wall_margin, range_cells
        self.counts: list[np.ndarray] = []
        self.gains: list[np.ndarray] = []

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:  # type: ignore[override]  # an oracle is reset with the ground truth (reset_planner)
        super().reset(ground_truth, protocol, seed)  # type: ignore[arg-type]  # GraphPlanner.reset keeps the map's frame only (map_frame)
        self.true_gain = TrueGain(ground_truth, protocol)

    def plan(self, observation: Observation):
        waypoints = super().plan(observation)  # updates the graph once and chooses as greedy_utility does
        graph = self.graph
        if graph is None:
            raise RuntimeError("reset() must be called before plan()")
        robot = self.robot_node(observation)
        dist, _ = graph.shortest_paths(robot)
        targets = self.reachable_useful(robot, dist)
        if targets.size:
            cells = graph.node_cells[targets]
            self.counts.append(gate_features(observation.belief, cells, self.range_cells, self.wall_margin))
            self.gains.append(self.true_gain.gains(observation.belief, cells))
        return waypoints


def gate_samples(
    ground_truth: GroundTruthMap, protocol: Protocol, wall_margin: int = 2, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """(counts (n, 3), true gains (n,)) of every reachable target at every decision of one greedy episode."""
    probe = _LabellingGreedy(wall_margin, protocol.sensor_range_cells)
    run_episode(ground_truth, probe, protocol, seed)
    if not probe.counts:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    return np.concatenate(probe.counts), np.concatenate(probe.gains)
