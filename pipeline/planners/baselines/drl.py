"""`drl`: the deep-RL exploration baseline of the paper's Table II (Cao et al. 2024), ours.

An attention policy over the observed graph (`pipeline.models.modeling_drl`) points at one node
of the robot's 5 x 5 lattice window per decision; it was trained by reinforcement learning in
`guide/Explore-v0` (the `train_drl` stage). The planner sees what the environment's agent saw:
the same lattice graph, visited marks and observation arrays (`observe_lattice`), and moves
only along known-free window edges, so its greedy choice here is the trained agent's there.
The episode ends when no reachable unvisited node sees a frontier cell.

A greedy policy can cycle in states it never met in training. After `stall_steps` decisions in
a row that reveal no free cell, the planner hands over to the shortest path toward the nearest
useful node until new cells appear (the same rule as `guide:mode=policy`'s); `stall_steps=0`
never hands over, and then the planner decides exactly as the environment's agent does.
"""

from __future__ import annotations

import warnings
from typing import Annotated, cast

import numpy as np

from pipeline.common.config import config_dataclass, maybe, text, whole
from pipeline.lattice.graph import LatticeGraph
from pipeline.lattice.spec import LatticeSpec
from pipeline.models.defaults import SHIPPED_DRL, cached_drl_policy, resolve_drl_path
from pipeline.models.modeling_drl import DRLPolicy
from pipeline.planners.config import PlannerConfig, option
from pipeline.planners.registry import register_planner
from pipeline.prediction.global_graph import GlobalGraphConfig
from pipeline.prediction.observed_graph import WindowTable, observe_lattice, window_moves
from pipeline.world.maps import MapFrame, map_frame
from pipeline.world.planner import Observation, Planner, Waypoint
from pipeline.world.protocol import Protocol, ProtocolMismatchWarning, model_input_differences
from pipeline.world.sensor import FREE

OBSERVED_GRAPH_INPUTS = ("cell_size", "node_resolution", "sensor_range", "utility_range")  # region_size: unused


@config_dataclass
class DRLConfig(PlannerConfig):
    description = "DRL (Cao et al. 2024): graph attention + pointer over the robot's window, trained by PPO"
    objects = ("policy",)
    renamed = {"checkpoint": "policy_file"}

    policy_file: Annotated[str | None, maybe(text())] = option(
        None, "drl policy export [default: models/drl/policy.pt, else the shipped one]"
    )
    stall_steps: Annotated[int, whole(0, note="0 = never hand over")] = option(
        4,
        "decisions in a row that reveal no free cell before the nearest-frontier hand-over breaks a cycle (0: "
        "never; the policy alone, as in the environment)",
    )

    def model_slots(self) -> dict[str, str]:
        return {"policy_file": "drl"}


@register_planner("drl", DRLConfig)
class DRLPlanner(Planner):
    """The trained attention-pointer policy, one window step per decision (greedy)."""

    description = DRLConfig.description

    def __init__(self, config: DRLConfig = DRLConfig(), policy: DRLPolicy | None = None):
        self.trained_on: dict  # what the policy was trained on ({} for an injected one)
        if policy is not None:
            self.policy, self.trained_on, source = policy.eval(), {}, "injected drl policy"
        else:
            try:
                path = resolve_drl_path(config.policy_file)
            except FileNotFoundError as error:  # an option error, reported in one line like the others
                raise ValueError(str(error)) from None
            self.policy, self.trained_on = cached_drl_policy(path)
            source = f"drl policy {path if path != SHIPPED_DRL else '(shipped)'}"
        self.source, self.stall_steps = source, config.stall_steps
        self.description = f"{DRLConfig.description} [{source}]"
        self.graph_config = GlobalGraphConfig(max_nodes=self.policy.config.max_nodes, use_region_evaluation=False)

    def check_protocol(self, protocol: Protocol) -> None:
        if "protocol" not in self.trained_on:
            return
        differences = [
            d
            for d in model_input_differences(self.trained_on["protocol"], protocol)
            if d.split()[0] in OBSERVED_GRAPH_INPUTS
        ]
        if differences:
            warnings.warn(
                f"the {self.source} was trained at other protocol values ({', '.join(differences)}): its "
                "graph means something else here; retrain with `dvc repro train_drl` at your maps' values",
                ProtocolMismatchWarning,
            )

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        self.check_protocol(protocol)
        self.graph = LatticeGraph(LatticeSpec.for_map(map_frame(frame), protocol))
        self.table = WindowTable(self.graph)
        self.visited = np.zeros(self.graph.node_count, dtype=bool)
        self.free_cells, self.stalled, self.handovers = -1, 0, 0

    def observe(self, observation: Observation):
        """Fold the observation into the graph; (the observation arrays, the valid window slots)."""
        self.graph.update(observation.belief, observation.changed)
        self.visited[self.graph.nearest_node(observation.position)] = True
        view = observe_lattice(
            self.graph,
            self.table,
            observation.position,
            self.visited,
            self.graph_config,
            self.policy.config.max_neighbors,
        )
        return view, window_moves(self.graph, self.table, view.robot_node)

    def plan(self, observation: Observation) -> list[Waypoint]:
        view, moves = self.observe(observation)
        reachable = np.isfinite(view.distance) & ~self.visited & (self.graph.utility > 0)
        if not moves.any() or not reachable.any():
            return []
        arrays = {
            "features": view.features,
            "node_mask": view.node_mask,
            "neighbors": view.neighbors,
            "robot": view.robot_row,
        }
        free_cells = int(np.count_nonzero(observation.belief == FREE))
        self.stalled = 0 if free_cells > self.free_cells else self.stalled + 1
        self.free_cells = free_cells
        if self.stall_steps and self.stalled >= self.stall_steps:
            self.handovers += 1
            node = self.nearest_useful_step(view, reachable)
        else:
            node = int(self.table.neighbour[view.robot_node, self.policy.predict_action(arrays, moves)])
        return [cast(Waypoint, tuple(map(float, self.graph.node_world[node])))]

    def nearest_useful_step(self, view, reachable: np.ndarray) -> int:
        """The first node on the shortest known path to the nearest reachable unvisited node that
        sees at least two frontier cells (any, when none does); equally near, the one seeing more."""
        useful = np.flatnonzero(reachable & (self.graph.utility >= 2))
        if useful.size == 0:
            useful = np.flatnonzero(reachable)
        order = np.lexsort((-self.graph.utility[useful], np.round(view.distance[useful], 6)))
        return int(self.graph.path_from_predecessors(view.predecessors, int(useful[order[0]]))[1])
