"""The planner interface, the registry of planner names, and the lattice-graph planner base."""

from __future__ import annotations

import math
import numbers
from abc import ABC, abstractmethod
from typing import Callable, TypeVar

import cv2
import numpy as np

from pipeline.frontier import FRONTIER_MIN_UNKNOWN_NEIGHBOURS
from pipeline.graph import LatticeGraph, LatticeSpec
from pipeline.maps import GroundTruthMap
from pipeline.protocol import Protocol
from pipeline.simulator import Observation
from pipeline.sliver_gate import SHIPPED_GATE, SliverGate, load_gate, resolve_gate_path

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

    def check_protocol(self, protocol: Protocol) -> None:
        """Warn (`ProtocolMismatchWarning`) when a trained model of this planner was trained at other
        protocol values than `protocol`; planners without trained models have nothing to say."""


class UnknownPlannerError(KeyError):
    """A planner name that is not registered. A KeyError (a failed lookup), printed as plain
    text rather than KeyError's quoted repr, so that it reads as the one-line user error it is."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "unknown planner"


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
        raise UnknownPlannerError(f"unknown planner {name!r}; choose from: {', '.join(names)}")
    return _REGISTRY[name]


def make_planner(name: str, **options) -> Planner:
    """A fresh planner instance by its registered name."""
    return planner_class(name)(**options)


# ----------------------------------------------------------------------------- option checks
# Constructors check their options with these, so that a value that makes no sense fails at
# once with a ValueError naming the option, the value and the valid range (the benchmark turns
# it into "error: planner 'label': <message>" before any episode runs). Every comparison is
# written so that NaN fails it.
def require(condition: bool, message: str) -> None:
    """ValueError(message) unless `condition`."""
    if not condition:
        raise ValueError(message)


def check_int(name: str, value, minimum: int = 1, maximum: int | None = None, note: str = "") -> None:
    """ValueError unless `value` is a whole number in minimum..maximum (no upper bound when None).

    `note` (e.g. "0 = off") is added to the message after the range.
    """
    whole = isinstance(value, numbers.Integral) or (isinstance(value, float) and value.is_integer())
    ok = whole and value >= minimum and (maximum is None or value <= maximum)
    rule = f">= {minimum}" if maximum is None else f"in {minimum}..{maximum}"
    if not whole:
        rule = f"an integer {rule}"
    shown = value if isinstance(value, numbers.Real) and not isinstance(value, bool) else repr(value)
    require(ok, f"{name} must be {rule}{f' ({note})' if note else ''}, got {shown}")


def check_number(
    name: str,
    value,
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
    none: str | None = None,
    allow_inf: bool = False,
    note: str = "",
) -> None:
    """ValueError unless `value` is a real number in the interval from `low` to `high`
    (closed ends unless `low_open` / `high_open`; None: unbounded on that side).

    NaN is always refused, +-inf unless `allow_inf` (the interval still applies). `none`, when
    given, says what None means, and None is then accepted; `note` is added to the message.
    """
    if value is None and none is not None:
        return
    number = isinstance(value, numbers.Real) and not isinstance(value, bool)
    v = float(value) if number else math.nan
    ok = number and not math.isnan(v) and (allow_inf or math.isfinite(v))
    ok = ok and (low is None or (v > low if low_open else v >= low))
    ok = ok and (high is None or (v < high if high_open else v <= high))
    if low is not None and high is not None:
        rule = f"a number in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    else:
        rule = "a number" if allow_inf else "a finite number"
        if low is not None:
            rule += f" {'>' if low_open else '>='} {low:g}"
        if high is not None:
            rule += f" {'<' if high_open else '<='} {high:g}"
    notes = "; ".join(n for n in (note, f"None = {none}" if none is not None else "") if n)
    shown = value if number else repr(value)
    require(ok, f"{name} must be {rule}{f' ({notes})' if notes else ''}, got {shown}")


class GraphPlanner(Planner):
    """A planner that keeps the lattice graph of Sec. IV-A up to date from each observation.

    With the sliver gate (`sliver_gate=True`; `sliver_gate_default` per planner), its useful
    nodes are first only those the gate calls big (`pipeline.sliver_gate`); the fitted gate in
    models/ when present, else the shipped one, unless `gate_file` names another.
    """

    sliver_gate_default = False

    def __init__(self, min_utility: int = 2, sliver_gate: bool | None = None, gate_file: str | None = None):
        # A node is a target when it sees at least min_utility frontier cells: below 1, nodes that
        # see nothing would be targets too and the robot would tour every node.
        check_int("min_utility", min_utility, 1)
        require(sliver_gate is None or isinstance(sliver_gate, bool), f"sliver_gate must be true or false, got {sliver_gate!r}")
        self.min_utility = min_utility
        self.graph: LatticeGraph | None = None
        self.rng = np.random.default_rng(0)
        self.gate: SliverGate | None = None
        self.gate_source = "no sliver gate"
        if self.sliver_gate_default if sliver_gate is None else sliver_gate:
            path = resolve_gate_path(gate_file)
            self.gate = load_gate(path)[0]
            self.gate_source = f"sliver gate {path if path != SHIPPED_GATE else '(shipped)'}"
            # Which gate a run used belongs in its run.json: gated routes move with the gate's fit.
            self.description = f"{self.description} [{self.gate_source}]"
        elif gate_file is not None:
            raise ValueError("gate_file is given but the sliver gate is off; add sliver_gate=true")
        self._gated: tuple[np.ndarray, np.ndarray] | None = None  # (useful nodes, those the gate passes) this decision
        # The gate's verdict per node, kept until a belief change comes within its reach: a
        # verdict reads only the belief around its node, and most nodes are far from each scan.
        self._gate_known, self._gate_big = np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        self.graph = LatticeGraph(LatticeSpec.for_map(ground_truth, protocol))
        self.visited = np.zeros(self.graph.node_count, dtype=bool)
        self.protocol = protocol
        self.rng = np.random.default_rng(seed)
        self._gate_known = np.zeros(self.graph.node_count, dtype=bool)
        self._gate_big = np.zeros(self.graph.node_count, dtype=bool)

    def update_graph(self, observation: Observation) -> LatticeGraph:
        """Fold the cells changed since the last decision into the graph; returns it."""
        if self.graph is None:
            raise RuntimeError("reset() must be called before plan()")
        self.graph.update(observation.belief, observation.changed)
        if self.gate is not None:
            self._forget_gate_verdicts(observation.belief.shape, observation.changed)
        self.robot = self.graph.nearest_node(observation.position)
        self.visited[self.robot] = True
        self.belief = observation.belief
        self._gated = None
        return self.graph

    def _forget_gate_verdicts(self, shape: tuple[int, int], changed: np.ndarray | None) -> None:
        """Drop the gate verdicts of the nodes within the gate's reach of a changed cell (all on
        the first observation, whose changes are not listed)."""
        if changed is None or self._gate_known.size != self.graph.node_count:
            self._gate_known = np.zeros(self.graph.node_count, dtype=bool)
            self._gate_big = np.zeros(self.graph.node_count, dtype=bool)
            return
        if changed.size == 0 or not self._gate_known.any():
            return
        known = np.nonzero(self._gate_known)[0]
        touched = np.zeros(shape, dtype=np.uint8)
        touched.flat[changed] = 1
        total = cv2.integral(touched)  # (rows + 1, cols + 1) running sums: one box sum per node
        reach = self.gate.reach_cells(self.protocol.sensor_range_cells)
        cols, rows = self.graph.node_cells[known, 0], self.graph.node_cells[known, 1]
        top, bottom = np.clip(rows - reach, 0, shape[0]), np.clip(rows + reach + 1, 0, shape[0])
        left, right = np.clip(cols - reach, 0, shape[1]), np.clip(cols + reach + 1, 0, shape[1])
        inside = total[bottom, right] - total[top, right] - total[bottom, left] + total[top, left]
        self._gate_known[known[inside > 0]] = False

    def robot_node(self, observation: Observation) -> int:
        assert self.graph is not None
        return self.graph.nearest_node(observation.position)

    def useful_nodes(self, dist: np.ndarray | None = None) -> np.ndarray:
        """Unvisited free nodes whose frontier utility is worth a visit.

        A visited node that still sees frontier cells saw them from there already without
        clearing them (grazing rays); going back would loop, so it is not a target. With the
        sliver gate, only those it calls big while the robot can reach any of them (`dist`:
        known-graph distances from the robot's node, computed when not given); a gate that
        passed only unreachable nodes would leave the robot nothing to do.
        """
        useful = self.ungated_useful_nodes()
        if self.gate is None or useful.size == 0:
            return useful
        if self._gated is None or not np.array_equal(self._gated[0], useful):
            big = self.gate_verdicts(useful)
            if big.any():
                dist = self.graph.shortest_paths(self.robot)[0] if dist is None else dist
                big &= np.isfinite(dist[useful])
            self._gated = (useful, useful[big] if big.any() else useful)
        return self._gated[1]

    def ungated_useful_nodes(self) -> np.ndarray:
        """Unvisited free nodes that see at least `min_utility` frontier cells (any, when none
        does), before the gate."""
        assert self.graph is not None
        useful = np.nonzero((self.graph.utility >= self.min_utility) & ~self.visited)[0]
        if useful.size == 0:
            useful = np.nonzero((self.graph.utility > 0) & ~self.visited)[0]
        return useful

    def gate_verdicts(self, nodes: np.ndarray) -> np.ndarray:
        """Whether the gate calls each of `nodes` big, judged now for those without a kept verdict."""
        unjudged = nodes[~self._gate_known[nodes]]
        if unjudged.size:
            self._gate_big[unjudged] = self.gate.passes(self.belief, self.graph.node_cells[unjudged],
                                                        self.protocol.sensor_range_cells, self._gate_frontier())
            self._gate_known[unjudged] = True
        return self._gate_big[nodes]

    def _gate_frontier(self) -> np.ndarray | None:
        """The graph's frontier when it is the one the gate reads (`frontier_mask`'s default), else None."""
        same_rule = self.graph.spec.frontier_min_unknown_neighbours == FRONTIER_MIN_UNKNOWN_NEIGHBOURS
        return self.graph.frontier if same_rule else None

    def reachable_useful(self, robot: int, dist: np.ndarray) -> np.ndarray:
        """The useful nodes other than the robot's own that known-free paths reach (`dist` from the robot)."""
        targets = self.useful_nodes(dist)
        return targets[np.isfinite(dist[targets]) & (targets != robot)]

    def nearest_useful_step(self, robot: int) -> list[Waypoint]:
        """One step along the shortest path to the nearest useful node (Yamauchi's rule).

        Among equally near nodes the one that sees more frontier wins; [] when none is reachable.
        """
        graph = self.graph
        assert graph is not None
        dist, pred = graph.shortest_paths(robot)
        targets = self.reachable_useful(robot, dist)
        if targets.size == 0:
            return []
        order = np.lexsort((-graph.utility[targets], np.round(dist[targets], 6)))
        return self.waypoints_along(graph.path_from_predecessors(pred, int(targets[order[0]])))

    def waypoints_along(self, path: list[int], max_waypoints: int = 1) -> list[Waypoint]:
        """The first `max_waypoints` nodes of a path after the robot's own node, in metres."""
        assert self.graph is not None
        return [tuple(map(float, self.graph.node_world[n])) for n in path[1 : 1 + max_waypoints]]
