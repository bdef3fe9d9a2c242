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
            pred, ranked = self.ranked_targets(episode.observe())
            if ranked.size == 0:
                return None
            if committed and (target == self.robot or target not in set(ranked.tolist())):
                committed = False
            if not committed:
                target = int(ranked[0])

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
