"""The planner interface, the registry of planner names, and the lattice-graph planner base."""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Callable, TypeVar

import numpy as np

from pipeline.graph import LatticeGraph, LatticeSpec
from pipeline.maps import GroundTruthMap
from pipeline.protocol import Protocol
from pipeline.simulator import Observation

Waypoint = tuple[float, float]
_REGISTRY: dict[str, type["Planner"]] = {}
P = TypeVar("P", bound=type["Planner"])


class Planner(ABC):
    """Proposes the next waypoint(s); the simulator moves there in order, sensing after each.

    `reset` is called once per episode with the ground truth, which only oracle planners
    may look at (`uses_ground_truth = True`); every other planner must decide from the
    observation alone.
    """

    name: str = ""
    description: str = ""
    uses_ground_truth: bool = False
    ignores_motion_rule: bool = False  # only the ground-truth "Optimal" reference may set this
    needs_policy: bool = False  # True: needs a trained diffusion policy (models/ or the shipped default)

    @abstractmethod
    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        """Prepare for a new episode."""

    @abstractmethod
    def plan(self, observation: Observation) -> list[Waypoint]:
        """Next lattice waypoints in world metres; [] when nothing reachable is left to explore."""


def register_planner(name: str) -> Callable[[P], P]:
    """Class decorator: make a planner available under a lower-case `name`."""
    if not name.isidentifier() or name != name.lower():
        raise ValueError(f"planner names are lower-case identifiers, got {name!r}")

    def decorate(cls: P) -> P:
        if name in _REGISTRY and _REGISTRY[name] is not cls:
            raise ValueError(f"planner name {name!r} is already registered")
        cls.name = name
        _REGISTRY[name] = cls
        return cls

    return decorate


def planner_names() -> list[str]:
    import pipeline.planners  # noqa: F401  (registers the built-in planners)

    return sorted(_REGISTRY)


def planner_class(name: str) -> type[Planner]:
    names = planner_names()
    if name not in _REGISTRY:
        raise KeyError(f"unknown planner {name!r}; choose from: {', '.join(names)}")
    return _REGISTRY[name]


def make_planner(name: str, **options) -> Planner:
    """A fresh planner instance by its registered name."""
    return planner_class(name)(**options)


class GraphPlanner(Planner):
    """A planner that keeps the lattice graph of Sec. IV-A up to date from each observation."""

    def __init__(self, min_utility: int = 2):
        self.min_utility = min_utility
        self.graph: LatticeGraph | None = None
        self.rng = np.random.default_rng(0)

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        self.graph = LatticeGraph(LatticeSpec.for_map(ground_truth, protocol))
        self.visited = np.zeros(self.graph.node_count, dtype=bool)
        self.protocol = protocol
        self.rng = np.random.default_rng(seed)

    def update_graph(self, observation: Observation) -> LatticeGraph:
        """Fold the cells changed since the last decision into the graph; returns it."""
        if self.graph is None:
            raise RuntimeError("reset() must be called before plan()")
        self.graph.update(observation.belief, observation.changed)
        self.visited[self.graph.nearest_node(observation.position)] = True
        return self.graph

    def robot_node(self, observation: Observation) -> int:
        assert self.graph is not None
        return self.graph.nearest_node(observation.position)

    def useful_nodes(self) -> np.ndarray:
        """Unvisited free nodes whose frontier utility is worth a visit.

        A visited node that still sees frontier cells saw them from there already without
        clearing them (grazing rays); going back would loop, so it is not a target.
        """
        assert self.graph is not None
        useful = np.nonzero((self.graph.utility >= self.min_utility) & ~self.visited)[0]
        if useful.size == 0:
            useful = np.nonzero((self.graph.utility > 0) & ~self.visited)[0]
        return useful

    def nearest_useful_step(self, robot: int) -> list[Waypoint]:
        """One step along the shortest path to the nearest useful node (Yamauchi's rule).

        Among equally near nodes the one that sees more frontier wins; [] when none is reachable.
        """
        graph = self.graph
        assert graph is not None
        dist, pred = graph.shortest_paths(robot)
        targets = self.useful_nodes()
        targets = targets[np.isfinite(dist[targets]) & (targets != robot)]
        if targets.size == 0:
            return []
        order = np.lexsort((-graph.utility[targets], np.round(dist[targets], 6)))
        return self.waypoints_along(graph.path_from_predecessors(pred, int(targets[order[0]])))

    def waypoints_along(self, path: list[int], max_waypoints: int = 1) -> list[Waypoint]:
        """The first `max_waypoints` nodes of a path after the robot's own node, in metres."""
        assert self.graph is not None
        return [tuple(map(float, self.graph.node_world[n])) for n in path[1 : 1 + max_waypoints]]
