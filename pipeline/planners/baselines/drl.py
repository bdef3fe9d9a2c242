"""`drl`: the deep-RL exploration baseline of the paper's Table II (Cao et al. 2024), ours.

An attention policy over the observed graph (`pipeline.models.modeling_drl`) points at one node
of the robot's 5 x 5 lattice window per decision; it was trained by reinforcement learning in
`guide/Explore-v0` (the `train_drl` stage). The planner sees what the environment's agent saw:
the same lattice graph, visited marks and observation arrays (`observe_lattice`), and moves
only along known-free window edges, so its greedy choice here is the trained agent's there.
The episode ends when no reachable unvisited node sees a frontier cell.
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass

import numpy as np

from pipeline.lattice.graph import LatticeGraph, LatticeSpec
from pipeline.models.defaults import SHIPPED_DRL, cached_drl_policy, resolve_drl_path
from pipeline.models.modeling_drl import DRLPolicy
from pipeline.planners.config import PlannerConfig, option
from pipeline.planners.registry import register_planner
from pipeline.prediction.global_graph import GlobalGraphConfig
from pipeline.prediction.observed_graph import WindowTable, observe_lattice, window_moves
from pipeline.world.maps import GroundTruthMap
from pipeline.world.planner import Observation, Planner, Waypoint
from pipeline.world.protocol import Protocol, ProtocolMismatchWarning, model_input_differences


@dataclass(frozen=True)
class DRLConfig(PlannerConfig):
    description = "DRL (Cao et al. 2024): graph attention + pointer over the robot's window, trained by PPO"
    objects = ("policy",)

    checkpoint: str | None = option(None, "drl policy export [default: models/drl/policy.pt, else the shipped one]")


@register_planner("drl", DRLConfig)
class DRLPlanner(Planner):
    """The trained attention-pointer policy, one window step per decision (greedy)."""

    description = DRLConfig.description

    def __init__(self, config: DRLConfig = DRLConfig(), policy: DRLPolicy | None = None):
        if policy is not None:
            self.policy, self.trained_on, source = policy.eval(), {}, "injected drl policy"
        else:
            try:
                path = resolve_drl_path(config.checkpoint)
            except FileNotFoundError as error:  # an option error, reported in one line like the others
                raise ValueError(str(error)) from None
            self.policy, self.trained_on = cached_drl_policy(path)
            source = f"drl policy {path if path != SHIPPED_DRL else '(shipped)'}"
        self.source = source
        self.description = f"{DRLConfig.description} [{source}]"
        self.graph_config = GlobalGraphConfig(max_nodes=self.policy.config.max_nodes, use_region_evaluation=False)

    def check_protocol(self, protocol: Protocol) -> None:
        if "protocol" not in self.trained_on:
            return
        differences = model_input_differences(self.trained_on["protocol"], protocol)
        if differences:
            warnings.warn(f"the {self.source} was trained at other protocol values ({', '.join(differences)}): its "
                          "graph means something else here; retrain with `dvc repro train_drl` at your maps' values",
                          ProtocolMismatchWarning)

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        self.check_protocol(protocol)
        self.graph = LatticeGraph(LatticeSpec.for_map(ground_truth, protocol))
        self.table = WindowTable(self.graph)
        self.visited = np.zeros(self.graph.node_count, dtype=bool)

    def observe(self, observation: Observation):
        """Fold the observation into the graph; (the observation arrays, the valid window slots)."""
        self.graph.update(observation.belief, observation.changed)
        self.visited[self.graph.nearest_node(observation.position)] = True
        view = observe_lattice(self.graph, self.table, observation.position, self.visited, self.graph_config,
                               self.policy.config.max_neighbors)
        return view, window_moves(self.graph, self.table, view.robot_node)

    def plan(self, observation: Observation) -> list[Waypoint]:
        view, moves = self.observe(observation)
        reachable = np.isfinite(view.distance) & ~self.visited & (self.graph.utility > 0)
        if not moves.any() or not reachable.any():
            return []
        arrays = {"features": view.features, "node_mask": view.node_mask, "neighbors": view.neighbors,
                  "robot": view.robot_row}
        slot = self.policy.predict_action(arrays, moves)
        node = int(self.table.neighbour[view.robot_node, slot])
        return [tuple(map(float, self.graph.node_world[node]))]
