"""GUIDE's decision-maker (Sec. IV-C): a diffusion policy conditioned on the global graph.

At every decision:

1. Environmental extraction (Sec. IV-A): fold the new scan into the lattice graph; the robot's
   node and the useful nodes it can reach (`locate`). Nothing reachable left: the episode ends.
2. Global graph inference (Sec. IV-B): predict the free nodes V_p in unknown space
   (Algorithm 1), keep those in regions of high score r(g) and boost utilities u(v)
   (`update_global_graph`); `guide_noregion` keeps every prediction, `dare` predicts nothing.
3. Observation (Sec. IV-C): the global graph padded to the policy's node count, nearest nodes
   first; the last T_o of them condition the policy.
4. Sampling: T_p lattice steps sampled with K denoising steps, `candidates` plans in one
   batched pass; the plan that reaches the most new frontier per metre wins (`rank_plans`;
   `candidates=1` is the paper's single sample).
5. Receding horizon: the first T_a steps are executed, one waypoint per decision so that
   every intermediate position is observed, as in the expert data; then sample again.

Each sampled step becomes a move the motion rule allows (`diffusion.feasible_move`). A step
that stays put, or `stall_steps` moves that reveal nothing, hands over to one step along the
shortest path to the nearest useful node until new cells appear.

This is the `mode=policy` planner of the registered `guide`, `guide_noregion` and `dare`
(`pipeline.planners.guide.variants`). Their default, `mode=tour`, is our tour vote
(`pipeline.planners.extensions.tour_vote`), which uses the same policy to vote on the global
graph's frontier tour instead of driving its plans.
"""

from __future__ import annotations

import numpy as np
from scipy.sparse.csgraph import dijkstra

from pipeline.planners.guide.configuration_guide import GuideConfig
from pipeline.planners.guide.diffusion import attach_policy, drive, feasible_move
from pipeline.planners.predicting import GlobalGraphPlanner
from pipeline.prediction.global_graph import KNOWN
from pipeline.prediction.node_predictor import InpaintFn
from pipeline.world.maps import GroundTruthMap
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE

LATER_STEP_WEIGHT = 0.8  # a plan's k-th step counts 0.8^k of its utility: near gains are surer


class GuidePlanner(GlobalGraphPlanner):
    """The diffusion policy on the region-evaluated global graph, receding horizon (Sec. IV-C)."""

    def __init__(self, config: GuideConfig = GuideConfig(), inpaint: InpaintFn | None = None, policy=None,
                 name: str = "guide"):
        super().__init__(config, inpaint)
        self.diffusion = attach_policy(self, config, name, policy)
        self.action_steps, self.stall_steps = self.diffusion.action_steps, int(config.stall_steps)
        self.description = (f"{config.description} [mode policy; policy {self.diffusion.source}; "
                            f"{self.predictor_source}; {self.gate_source}; K={self.diffusion.num_inference_steps}]")

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        super().reset(ground_truth, protocol, seed)
        self.diffusion.reset(seed)
        self.queue: list[np.ndarray] = []  # the sampled steps (with their soft directions) still to execute
        self.moves_without_news = 0
        self.decisions = 0
        self.fallbacks = 0

    def plan(self, observation: Observation) -> list[Waypoint]:
        graph, robot, _, _, useful = self.locate(observation)  # 1. the lattice graph (Sec. IV-A)
        if useful.size == 0:
            return []  # nothing reachable is left to explore
        new_free = observation.changed is None or bool(np.any(observation.belief.reshape(-1)[observation.changed] == FREE))
        self.moves_without_news = 0 if new_free else self.moves_without_news + 1
        self.update_global_graph(observation)  # 2. predictions and region evaluation (Sec. IV-B)
        self.diffusion.observe(self.global_graph, observation.position)  # 3. the policy's observation, last T_o
        self.decisions += 1
        move, sampled = None, False
        if self.moves_without_news < self.stall_steps:
            if not self.queue:  # 4. sample T_p steps (K denoising steps each), keep the best plan's first T_a
                sampled = True
                steps, directions = self.sample_steps()
                self.queue = [np.concatenate([s, d]) for s, d in zip(steps[: self.action_steps], directions[: self.action_steps])]
            planned = self.queue.pop(0)  # 5. receding horizon: the next of the T_a steps
            move = feasible_move(graph, robot, planned[:2].astype(np.int64), planned[2:])
            exact = move is not None and np.array_equal(graph.node_ij[move] - graph.node_ij[robot], planned[:2].astype(np.int64))
            if not exact:
                self.queue = []  # the rest of the chunk assumed this step: re-plan next time
        if move is None:  # the policy stays put, or nothing new for stall_steps moves: the nearest useful node
            self.fallbacks += 1
            self.queue = []
            waypoints = self.nearest_useful_step(robot)
            self.last_decision = {"fallback": True, "sampled": sampled, "fallback_share": self.fallbacks / self.decisions}
            return waypoints
        self.last_decision = {"fallback": False, "sampled": sampled, "fallback_share": self.fallbacks / self.decisions}
        return [tuple(map(float, graph.node_world[move]))]

    def sample_steps(self) -> tuple[np.ndarray, np.ndarray]:
        """(T_p, 2) lattice steps and (T_p, 2) soft directions: the best of the sampled plans."""
        deltas, expected = self.diffusion.sample()
        best = self.rank_plans(deltas, expected) if self.diffusion.candidates > 1 else 0
        return deltas[best], expected[best]

    def rank_plans(self, deltas: np.ndarray, expected: np.ndarray) -> int:
        """Index of the sampled plan that sees the most new frontier per metre when driven on the known graph.

        Each candidate's T_p steps are mapped to feasible moves as they would be executed; its
        score is the global graph's utility u(v) (frontier utility boosted by the predicted nodes
        in range; plain frontier utility for `dare`) of the distinct unvisited nodes it reaches,
        with each later step weighted less, over its length. Plans that reach no frontier are
        ordered by how close they end to the nearest useful node (shortest path on the known
        graph), so that in explored space the proposal that heads toward unexplored space wins.
        Ties keep the first sample.
        """
        graph = self.graph
        assert graph is not None
        robot = int(np.argmin(np.hypot(*(graph.node_world - self.diffusion.history[-1].positions[0]).T)))
        useful = self.useful_nodes()
        to_useful = (
            dijkstra(graph.adjacency(), directed=False, indices=useful, min_only=True)
            if useful.size else np.zeros(graph.node_count)
        )
        utility = np.zeros(graph.node_count)  # u(v) of the global graph's known nodes (Sec. IV-B.3)
        gg = self.global_graph
        known = gg.types == KNOWN
        utility[gg.lattice_ids[known]] = gg.utility[known]
        scores = np.zeros(len(deltas))
        scale = graph.spec.node_resolution / 4.0  # lengths in metres of the 4 m benchmark lattice, at any scale
        for c, path in enumerate(drive(graph, robot, deltas, expected)):
            seen, gain, length = set(), 0.0, 0.0
            for k, (node, nxt) in enumerate(zip(path[:-1], path[1:])):
                length += float(np.hypot(*(graph.node_world[nxt] - graph.node_world[node])))
                if nxt not in seen and not self.visited[nxt]:
                    gain += (LATER_STEP_WEIGHT**k) * float(utility[nxt])
                seen.add(nxt)
            end = path[-1]
            remaining = float(to_useful[end]) if np.isfinite(to_useful[end]) else 1e6
            scores[c] = gain / (length / scale + 1.0) - 1e-6 * remaining / scale
        return int(np.argmax(scores))
