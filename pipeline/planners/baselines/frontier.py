"""Classical frontier planners on the lattice graph: nearest frontier and greedy utility."""

from __future__ import annotations

from typing import cast

import numpy as np

from pipeline.common.config import config_dataclass
from pipeline.planners.graph_planner import GatedPlannerConfig, GraphPlanner
from pipeline.planners.registry import register_planner
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.simulator import Episode


@config_dataclass
class NearestFrontierConfig(GatedPlannerConfig):
    description = "Yamauchi: shortest path to the nearest node that sees frontier cells"


@config_dataclass
class GreedyUtilityConfig(GatedPlannerConfig):
    description = "greedy: frontier utility divided by shortest-path cost"


@register_planner("nearest_frontier", NearestFrontierConfig)
class NearestFrontierPlanner(GraphPlanner):
    """Yamauchi's frontier exploration: go to the nearest node that sees frontier cells."""

    description = NearestFrontierConfig.description

    def __init__(self, config: NearestFrontierConfig = NearestFrontierConfig()):
        super().__init__(config)

    def plan(self, observation: Observation) -> list[Waypoint]:
        self.update_graph(observation)
        return self.nearest_useful_step(self.robot_node(observation))


@register_planner("greedy_utility", GreedyUtilityConfig)
class GreedyUtilityPlanner(GraphPlanner):
    """Greedy information gain: the node with the most frontier utility per metre of path."""

    description = GreedyUtilityConfig.description

    def __init__(self, config: GatedPlannerConfig = GreedyUtilityConfig()):
        super().__init__(config)
        self.last_decision: dict = {}

    def ranked_targets(self, observation: Observation) -> tuple[np.ndarray, np.ndarray]:
        """(known-graph predecessors from the robot, its reachable targets by utility per metre, best first)."""
        graph = self.update_graph(observation)
        robot = self.robot_node(observation)
        dist, pred = graph.shortest_paths(robot)
        targets = self.reachable_useful(robot, dist)
        return pred, targets[np.argsort(-graph.utility[targets] / dist[targets], kind="stable")]

    def plan(self, observation: Observation) -> list[Waypoint]:
        pred, ranked = self.ranked_targets(observation)
        if ranked.size == 0:
            self.last_decision = {}
            return []
        assert self.graph is not None
        target = int(ranked[0])
        self.last_decision = {"target": target}  # the node it heads for (a DAgger teacher's label)
        return self.waypoints_along(self.graph.path_from_predecessors(pred, target))

    def finish_episode(self, episode: Episode, target: int, pred: np.ndarray, per_target: bool = False) -> float | None:
        """Head for `target` until it is reached or stops being a target, then this planner's rule, on
        `episode` (the lookaheads run this on a copy of themselves and of an episode). The distance at
        completion; inf past the step limit; None when no target is left before completion.

        With `per_target` each chosen target's whole shortest path is walked (scanning at every
        node) before the next choice: a third of the graph updates of choosing at every node, no
        change of mind on the way (the fast rollouts of `guide:lookahead`)."""
        if per_target:
            return self._finish_per_target(episode, target, pred)
        committed = True
        assert self.graph is not None
        while True:
            ended = self._move_to(episode, self.graph.path_from_predecessors(pred, target)[1])
            if ended is not None:
                return ended
            graph = self.update_graph(episode.observe())
            dist, pred = graph.shortest_paths(self.robot)
            if self._ranking_prefix(dist, 1).size == 0:
                return None
            if committed and (target == self.robot or not self._is_gated_target(target, dist)):
                committed = False
            if not committed:
                target = self._best_gated(dist)

    # The rollouts ask only for the best target and whether one target is still a target. So they
    # rank lazily: the gate is asked down the ungated ranking a few nodes at a time, instead of on
    # every useful node as `ranked_targets` does, and on a rollout copy whose graph keeps bounds
    # for utilities (`LatticeGraph.lazy_utilities`) only the nodes that reach the top are counted.
    # The choices are `ranked_targets`' own: a verdict reads only the belief around its node, and
    # a bound only falls when counted.
    def _ranking_prefix(self, dist: np.ndarray, count: int) -> np.ndarray:
        """The first `count` nodes of the ungated ranking: the reachable useful nodes by utility per
        metre, best first (ties by node id), with every utility in it counted exactly."""
        graph = self.graph
        assert graph is not None
        while True:
            kept = getattr(self, "_ranking", None)  # (utilities' version, dist, order): sorted once per change
            if kept is None or kept[0] != graph.utility_version or kept[1] is not dist:
                useful = self.ungated_useful_nodes()
                reachable = useful[np.isfinite(dist[useful]) & (useful != self.robot)]
                kept = (
                    graph.utility_version,
                    dist,
                    reachable[np.argsort(-graph.utility[reachable] / dist[reachable], kind="stable")],
                )
                self._ranking = kept
            order = kept[2]
            top = order[:count]
            if not graph.stale[top].any():  # below the top, a bound's score can only fall: the top stands
                return top
            bounds = order[: max(count, 4)]  # the next few too: one count for several
            graph.exact_utilities(bounds[graph.stale[bounds]])

    def _first_big(self, dist: np.ndarray, batch: int = 4) -> int | None:
        """The first node of the ungated ranking the gate calls big (None when none is), judging a few at a time."""
        start = 0
        while True:
            top = self._ranking_prefix(dist, start + batch)
            if top.size <= start:
                return None
            big = self.gate_verdicts(top[start:])
            if big.any():
                return int(top[start + int(np.argmax(big))])
            start = top.size

    def _best_gated(self, dist: np.ndarray) -> int:
        """`ranked_targets`' first target: the best node the gate calls big, else the best of all (the
        gate passes everything when it passes none)."""
        first = None if self.gate is None else self._first_big(dist)
        return int(self._ranking_prefix(dist, 1)[0]) if first is None else first

    def _is_gated_target(self, node: int, dist: np.ndarray) -> bool:
        """Whether `node` is among `ranked_targets`' targets."""
        graph = self.graph
        if self.visited[node] or node == self.robot or not np.isfinite(dist[node]):
            return False
        assert graph is not None
        graph.exact_utilities(np.array([node]))
        if graph.utility[node] < self.min_utility:
            if graph.utility[node] == 0:
                return False
            graph.exact_utilities(np.nonzero(graph.stale)[0])  # useful only when no node sees min_utility
            if not np.any(self.ungated_useful_nodes() == node):
                return False
        if self.gate is None or self.gate_verdicts(np.array([node]))[0]:
            return True
        return self._first_big(dist) is None

    def _finish_per_target(self, episode: Episode, target: int, pred: np.ndarray) -> float | None:
        assert self.graph is not None
        while True:
            for node in self.graph.path_from_predecessors(pred, target)[1:]:
                ended = self._move_to(episode, node)
                if ended is not None:
                    return ended
            pred, ranked = self.ranked_targets(episode.observe())
            if ranked.size == 0:
                return None
            target = int(ranked[0])

    def _move_to(self, episode: Episode, node: int) -> float | None:
        """One rollout move to a neighbouring `node`; the rollout's result if it ends there
        (the distance at completion, inf at the step limit), else None."""
        assert self.graph is not None
        for waypoint in self.graph.route_between(self.graph.nearest_node(episode.position), node):
            episode.move(waypoint)  # through the edge's door node first, where it has one
        if episode.complete:
            return float(cast(float, episode.completion_distance))
        if episode.steps >= self.protocol.max_steps:
            return np.inf
        return None
