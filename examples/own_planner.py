"""Your own planner on ours: registered by name, run by `guide explore` and `guide benchmark`.

A planner is reset with the map's frame (its extent, cell size and start: what a robot knows
before exploring) and then sees only observations. This one keeps the lattice graph of Sec. IV-A
(`GraphPlanner`) and walks to the useful node that sees the most frontier cells per metre.
"""

from __future__ import annotations

import argparse

import numpy as np

from pipeline.common.config import config_dataclass
from pipeline.planners import register_planner
from pipeline.planners.graph_planner import GraphPlanner, LatticePlannerConfig
from pipeline.world.maps import load_map
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode


@config_dataclass
class BestRatioConfig(LatticePlannerConfig):
    description = "the useful node with the most frontier cells per metre of path, one step at a time"


@register_planner("best_ratio", BestRatioConfig)
class BestRatioPlanner(GraphPlanner):
    def plan(self, observation):
        graph = self.update_graph(observation)
        dist, pred = graph.shortest_paths(self.robot)
        targets = self.reachable_useful(self.robot, dist)
        if targets.size == 0:
            return []  # nothing reachable is left to explore
        best = targets[np.argmax(graph.utility[targets] / dist[targets])]
        return self.waypoints_along(graph.path_from_predecessors(pred, int(best)))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("map", help="a maze PNG, a .npy grid or a ROS map YAML")
    result = run_episode(load_map(parser.parse_args().map), BestRatioPlanner(BestRatioConfig()), Protocol())
    print(f"best_ratio: {'complete' if result.complete else 'incomplete'} after {result.distance_m:.1f} m")
