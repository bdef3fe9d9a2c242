"""The lattice-graph planner base (Sec. IV-A): the graph kept up to date from each observation."""

from __future__ import annotations

import typing
from pathlib import Path
from typing import Annotated, cast

import cv2
import numpy as np

from pipeline.common.config import config_dataclass, flag, maybe, text, whole
from pipeline.lattice.frontier import FRONTIER_MIN_UNKNOWN_NEIGHBOURS
from pipeline.lattice.graph import LatticeGraph
from pipeline.lattice.spec import LatticeSpec
from pipeline.models.defaults import SHIPPED_GATE, resolve_gate_path
from pipeline.models.sliver_gate import load_gate
from pipeline.planners.config import PlannerConfig, option
from pipeline.world.maps import MapFrame, map_frame
from pipeline.world.planner import Observation, Planner, Waypoint
from pipeline.world.protocol import Protocol


@config_dataclass
class LatticePlannerConfig(PlannerConfig):
    """The options every lattice-graph planner has."""

    part = "targets on the lattice (Sec. IV-A)"

    min_utility: Annotated[int, whole(1)] = option(
        2,
        "a node is a target when it sees at least this many frontier cells (below 1, "
        "nodes that see nothing would be targets too and the robot would tour every node)",
    )


@config_dataclass
class GatedPlannerConfig(LatticePlannerConfig):
    """A lattice-graph planner that can leave slivers for later (`pipeline.models.sliver_gate`)."""

    part = "the sliver gate (ours)"

    sliver_gate: Annotated[bool, flag()] = option(
        False,
        "consider first only the targets the sliver gate calls big (their scan would "
        "reveal much); the rest only when none is",
    )
    gate_file: Annotated[str | None, maybe(text())] = option(
        None, "the fitted sliver gate [default: models/sliver_gate/sliver_gate.json, else the shipped one]"
    )

    def check(self) -> None:
        super().check()
        if self.gate_file is not None and not self.sliver_gate:
            raise ValueError("gate_file is given but the sliver gate is off; add sliver_gate=true")

    def model_slots(self) -> dict[str, str]:
        return {**super().model_slots(), **({"gate_file": "gate"} if self.sliver_gate else {})}


class Gate(typing.Protocol):
    """A sliver gate: a fitted `SliverGate`, or one that knows the ground truth (an oracle bound's)."""

    def reach_cells(self, range_cells: float) -> int: ...

    def passes(
        self, belief: np.ndarray, cells: np.ndarray, range_cells: float, frontier: np.ndarray | None = None
    ) -> np.ndarray: ...


class GraphPlanner(Planner):
    """A planner that keeps the lattice graph of Sec. IV-A up to date from each observation.

    With the sliver gate (a `GatedPlannerConfig` with `sliver_gate`), its useful nodes are first
    only those the gate calls big (`pipeline.models.sliver_gate`); the fitted gate in
    models/ when present, else the shipped one, unless `gate_file` names another.
    """

    def __init__(self, config: LatticePlannerConfig):
        self.config = config
        self.min_utility = config.min_utility
        self.graph: LatticeGraph | None = None
        self.rng = np.random.default_rng(0)
        self.gate: Gate | None = None
        self.gate_path: Path | None = None
        self.gate_source = "no sliver gate"
        if getattr(config, "sliver_gate", False):
            path = resolve_gate_path(cast(GatedPlannerConfig, config).gate_file)
            self.gate, self.gate_path = load_gate(path)[0], path
            self.gate_source = f"sliver gate {path if path != SHIPPED_GATE else '(shipped)'}"
            # Which gate a run used belongs in its run.json: gated routes move with the gate's fit.
            self.description = f"{self.description} [{self.gate_source}]"
        self._gated: tuple[np.ndarray, np.ndarray] | None = None  # (useful nodes, those the gate passes) this decision
        # The gate's verdict per node, kept until a belief change comes within its reach: a
        # verdict reads only the belief around its node, and most nodes are far from each scan.
        self._gate_known, self._gate_big = np.zeros(0, dtype=bool), np.zeros(0, dtype=bool)

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        frame = map_frame(frame)  # an oracle built on this planner passes its ground truth: only its frame is kept
        self.graph = LatticeGraph(LatticeSpec.for_map(frame, protocol))
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
        assert self.graph is not None
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
        assert self.gate is not None
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
        assert self.graph is not None
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
            assert self.graph is not None and self.gate is not None
            self._gate_big[unjudged] = self.gate.passes(
                self.belief, self.graph.node_cells[unjudged], self.protocol.sensor_range_cells, self._gate_frontier()
            )
            self._gate_known[unjudged] = True
        return self._gate_big[nodes]

    def _gate_frontier(self) -> np.ndarray | None:
        """The graph's frontier when it is the one the gate reads (`frontier_mask`'s default), else None."""
        assert self.graph is not None
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
        return [cast(Waypoint, tuple(map(float, self.graph.node_world[n]))) for n in path[1 : 1 + max_waypoints]]
