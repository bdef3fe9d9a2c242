"""Classical frontier planners on the lattice graph: nearest frontier and greedy utility."""

from __future__ import annotations

import numpy as np

from pipeline.planners.base import GraphPlanner, Waypoint, register_planner
from pipeline.simulator import Observation


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
