"""Classical frontier planners on the lattice graph: nearest frontier and greedy utility."""

from __future__ import annotations

import numpy as np

from pipeline.planners.base import GraphPlanner, Waypoint, register_planner
from pipeline.simulator import Episode, Observation


@register_planner("nearest_frontier")
class NearestFrontierPlanner(GraphPlanner):
    """Yamauchi's frontier exploration: go to the nearest node that sees frontier cells."""

    description = "Yamauchi: shortest path to the nearest node that sees frontier cells"

    def plan(self, observation: Observation) -> list[Waypoint]:
        self.update_graph(observation)
        return self.nearest_useful_step(self.robot_node(observation))


@register_planner("greedy_utility")
class GreedyUtilityPlanner(GraphPlanner):
    """Greedy information gain: the node with the most frontier utility per metre of path."""

    description = "greedy: frontier utility divided by shortest-path cost"

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
            return []
        return self.waypoints_along(self.graph.path_from_predecessors(pred, int(ranked[0])))

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
        while True:
            ended = self._move_to(episode, self.graph.path_from_predecessors(pred, target)[1])
            if ended is not None:
                return ended
            pred, order = self._ungated_ranking(episode.observe())
            if order.size == 0:
                return None
            if committed and (target == self.robot or not self._is_gated_target(target, order)):
                committed = False
            if not committed:
                target = self._best_gated(order)

    # The rollouts ask only for the best target and whether one target is still a target, so they
    # judge the gate lazily, down the ungated ranking, instead of on every useful node as
    # `ranked_targets` does: the same choices (a verdict reads only the belief around its node)
    # for about a quarter of the gate's fans.
    def _ungated_ranking(self, observation: Observation) -> tuple[np.ndarray, np.ndarray]:
        """(predecessors from the robot, its reachable useful nodes before the gate, by utility per
        metre, best first): `ranked_targets` without the gate."""
        graph = self.update_graph(observation)
        dist, pred = graph.shortest_paths(self.robot)
        useful = self.ungated_useful_nodes()
        reachable = useful[np.isfinite(dist[useful]) & (useful != self.robot)]
        return pred, reachable[np.argsort(-graph.utility[reachable] / dist[reachable], kind="stable")]

    def _first_big(self, order: np.ndarray, batch: int = 4) -> int | None:
        """Position in `order` of the first node the gate calls big (None when none is), judging a few at a time."""
        for start in range(0, order.size, batch):
            big = self.gate_verdicts(order[start : start + batch])
            if big.any():
                return start + int(np.argmax(big))
        return None

    def _best_gated(self, order: np.ndarray) -> int:
        """`ranked_targets`' first target from the ungated ranking `order`: the best node the gate
        calls big, else the best of all (the gate passes everything when it passes none)."""
        first = None if self.gate is None else self._first_big(order)
        return int(order[0 if first is None else first])

    def _is_gated_target(self, node: int, order: np.ndarray) -> bool:
        """Whether `node` is among `ranked_targets`' targets, from the ungated ranking `order`."""
        if not np.any(order == node):
            return False
        if self.gate is None or self.gate_verdicts(np.array([node]))[0]:
            return True
        return self._first_big(order) is None

    def _finish_per_target(self, episode: Episode, target: int, pred: np.ndarray) -> float | None:
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
        episode.move(tuple(map(float, self.graph.node_world[node])))
        if episode.complete:
            return float(episode.completion_distance)
        if episode.steps >= self.protocol.max_steps:
            return np.inf
        return None
