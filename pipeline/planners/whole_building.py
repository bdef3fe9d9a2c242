"""The whole building: every planner drives through door nodes, and stops only when nothing is left.

Under the door-aware graph (`Protocol.uses_door_graph`: the real robot's scale) every planner
`make_planner` builds is wrapped in `WholeBuilding`, which changes three things and nothing else:

- **Door nodes.** A planner's graph validates edges through door nodes
  (`pipeline.lattice.doors`); when it sends the robot along such an edge, the door node is put
  before the edge's far end, so each segment is known free.
- **Done means done.** When the planner's own rule finds nothing (no useful node it reaches,
  utilities at or under its threshold), the robot drives to the nearest frontier cell it can
  reach through passable cells at its radius (`pipeline.lattice.reachability`), as ARiADNE's ROS
  planner falls back on the nearest frontier; it returns [] (done) only when no such cell is left.
  A robot standing on such a cell clears it; one its navigation stops short of is tried again, up
  to MAX_TRIES straight drives, then given up. A planner whose own rule has run dry but which
  would still head for a node under its `min_utility` (a graph planner takes any node that sees
  a frontier cell when none sees enough) is not followed there: such a node counts a cell its
  rays only graze, which a robot stopping near it, not on it, may never clear, so a robot could
  tour those nodes without end. The cell-level fallback decides instead, and it ends.
- **Onward.** A robot that asks again before the end of a plan (a robot session drives a plan's
  first waypoint, then asks) and stands off the lattice (at a door node, on the way to a
  fallback target) goes on with that plan from where it stands, rather than back to the lattice:
  a fallback until its target is cleared or given up.
- **Back to the lattice.** After a fallback the robot stands off the lattice; its next decision
  takes it by the shortest passable path to the nearest known-free lattice node, where the
  planner's graph has it again.

`decision_kind` says which of "planner", "fallback", "rejoin" or "done" the last decision was;
`fallbacks` counts the decisions that were not the planner's own (fallbacks and rejoins). At the
maze scale (DARE's lattice) the wrapper passes every call through unchanged.
"""

from __future__ import annotations

from typing import cast

import numpy as np

from pipeline.lattice.doors import via_waypoints
from pipeline.lattice.graph import NODE_FREE
from pipeline.lattice.reachability import open_frontier, path_to_nearest, waypoints_along
from pipeline.lattice.spec import LatticeSpec
from pipeline.planners.wrapper import PlannerWrapper, innermost
from pipeline.world.geometry import segment_is_known_free
from pipeline.world.maps import MapFrame, map_frame
from pipeline.world.planner import Observation, Planner, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.reachability import LEFTOVER_M2, clearance_cells, passable_mask
from pipeline.world.simulator import LATTICE_TOLERANCE_M, PLANNER_DECISION

PLANNER, FALLBACK, REJOIN, DONE = PLANNER_DECISION, "fallback", "rejoin", "done"
MAX_TRIES = 3  # straight drives to one fallback target before it is given up (a goal the robot never reaches)
REACHED_CELLS = 2  # a robot this many cells (Chebyshev) from a waypoint has reached it (a navigation stack stops near)


class WholeBuilding(PlannerWrapper):
    """`inner` on the door-aware graph, with the nearest-frontier fallback and the rejoin (module doc)."""

    def __init__(self, inner: Planner):
        super().__init__(inner)
        self.active = False
        self.decision_kind = PLANNER
        self.fallbacks = 0

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        self.inner.reset(frame, protocol, seed)
        self.active = protocol.uses_door_graph
        self.decision_kind, self.fallbacks = PLANNER, 0
        self._unseen: list[np.ndarray] | None = []  # changes the inner planner has not seen (None: all)
        self.pending: list[tuple[int, int]] = []  # the last plan's waypoint cells (col, row), to go on with
        self.pending_kind = PLANNER  # which decision made them
        self.goal: tuple[int, int] | None = None  # the last fallback's target cell
        if self.active:
            spec = LatticeSpec.for_map(map_frame(frame), protocol)
            self.spec, self.radius_cells = spec, protocol.robot_radius_cells
            cells = spec.world_to_cell(spec.node_indices() * spec.node_resolution)
            rows, cols = spec.shape
            inside = (cells[:, 0] >= 0) & (cells[:, 0] < cols) & (cells[:, 1] >= 0) & (cells[:, 1] < rows)
            self.node_mask = np.zeros(spec.shape, dtype=bool)
            self.node_mask[cells[inside, 1], cells[inside, 0]] = True
            self.tries = np.zeros(spec.shape, dtype=np.uint8)  # straight drives to each fallback target
            self.leftover_cells = max(1, int(round(LEFTOVER_M2 / protocol.cell_size**2)))

    def plan(self, observation: Observation) -> list[Waypoint]:
        if not self.active:
            return self.inner.plan(observation)
        passable = passable_mask(observation.belief, self.radius_cells)
        if not self._on_lattice(observation.position):
            onward = self._onward(observation, passable)
            if onward:
                return onward
            route = path_to_nearest(passable, passable & self.node_mask, observation.cell)
            if len(route) > 1:  # the inner planner sees these cells' changes at its next decision
                self._keep_changes(observation)
                self.decision_kind = REJOIN
                self.fallbacks += 1
                return self._metres(waypoints_along(passable, route))
        self.pending, self.goal = [], None
        waypoints = self.inner.plan(self._with_kept_changes(observation))
        if waypoints and self._rule_dry():
            waypoints = []
        if waypoints:
            self.decision_kind = PLANNER
            waypoints = self._through_doors(observation, passable, waypoints)
            self._remember(waypoints, PLANNER, None)
            return waypoints
        frontier = self._frontier(observation.belief)
        col, row = observation.cell
        if frontier[
            row, col
        ]:  # the robot stands on it (a session's robot stands near its cell): a visit did not clear it
            self.tries[row, col] = MAX_TRIES
            frontier[row, col] = False
        route = path_to_nearest(passable, frontier, observation.cell)
        if len(route) < 2:
            self.decision_kind = DONE
            return []
        return self._towards(passable, route, [], FALLBACK, route[-1])

    # ------------------------------------------------------------------ helpers
    def _rule_dry(self) -> bool:
        """Whether the inner planner's graph has no unvisited known-free node that sees
        `min_utility` frontier cells (False for a planner without a graph, visits or threshold).
        A utility the graph holds as a bound is at least the count, so "dry" is never said early."""
        base = innermost(self.inner)
        graph, visited, least = (getattr(base, name, None) for name in ("graph", "visited", "min_utility"))
        if graph is None or visited is None or least is None:
            return False
        return not np.any((graph.utility >= least) & ~visited & (graph.node_state == NODE_FREE))

    def _frontier(self, belief: np.ndarray) -> np.ndarray:
        """The open frontier cells (`open_frontier`) not yet given up."""
        frontier = open_frontier(belief, self.leftover_cells, self.spec.frontier_min_unknown_neighbours)
        return frontier & (self.tries < MAX_TRIES)

    def _onward(self, observation: Observation, passable: np.ndarray) -> list[Waypoint]:
        """The rest of the last plan from where the robot stands ([] when nothing of it is left: its
        waypoints reached, its fallback target cleared or given up, its way on blocked)."""
        pending, kind, goal = self.pending, self.pending_kind, self.goal
        self.pending, self.goal = [], None
        if not pending or goal is not None and not self._frontier(observation.belief)[goal[1], goal[0]]:
            return []
        here = observation.cell
        gaps = [max(abs(col - here[0]), abs(row - here[1])) for col, row in pending]
        nearest = int(np.argmin(gaps))
        rest = pending[nearest + 1 :] if gaps[nearest] <= REACHED_CELLS else pending[nearest:]
        if not rest:
            if goal is None:
                return []
            if here == goal:  # standing on it and it is still there: a visit does not clear it
                self.tries[goal[1], goal[0]] = MAX_TRIES
                return []
            rest = [goal]  # stopped short of it: again
        target = np.zeros(passable.shape, dtype=bool)
        target[rest[0][1], rest[0][0]] = True
        route = path_to_nearest(passable, target, here)
        if len(route) < 2:
            return []
        self._keep_changes(observation)  # the inner planner sees this decision's changes at its next
        return self._towards(passable, route, rest[1:], kind, goal)

    def _towards(
        self,
        passable: np.ndarray,
        route: list[tuple[int, int]],
        then: list[tuple[int, int]],
        kind: str,
        goal: tuple[int, int] | None,
    ) -> list[Waypoint]:
        """Waypoints along `route` (two cells or more), then the cells `then`; remembered to go on
        with. A fallback (`goal` its target) sent straight to its target counts a try."""
        corners = waypoints_along(passable, route) + then
        self.decision_kind = kind
        self.fallbacks += int(kind != PLANNER)
        if goal is not None and corners == [goal]:  # a robot standing on it clears it; one that stops
            self.tries[goal[1], goal[0]] += 1  # short of it, as a navigation stack may, tries again
        waypoints = self._metres(corners)
        self._remember(waypoints, kind, goal)
        return waypoints

    def _remember(self, waypoints: list[Waypoint], kind: str, goal: tuple[int, int] | None) -> None:
        cells = self.spec.world_to_cell(np.asarray(waypoints, dtype=np.float64).reshape(-1, 2))
        self.pending, self.pending_kind, self.goal = (
            [cast("tuple[int, int]", tuple(map(int, c))) for c in cells],
            kind,
            goal,
        )

    def _on_lattice(self, position: tuple[float, float]) -> bool:
        d = self.spec.node_resolution
        return all(abs(round(v / d) * d - v) <= LATTICE_TOLERANCE_M for v in position)

    def _through_doors(
        self, observation: Observation, passable: np.ndarray, waypoints: list[Waypoint]
    ) -> list[Waypoint]:
        cells = [
            cast("tuple[int, int]", tuple(map(int, c)))
            for c in self.spec.world_to_cell(np.asarray(waypoints, dtype=np.float64))
        ]
        if all(segment_is_known_free(passable, a, b) for a, b in zip([observation.cell, *cells[:-1]], cells)):
            return waypoints  # every segment straight: no door node to look for
        route = via_waypoints(passable, clearance_cells(observation.belief), observation.cell, cells)
        out: list[Waypoint] = []
        given = iter(waypoints)
        for cell, door in route:  # the planner's own waypoints stay exactly as it gave them
            out.append(self._metres([cell])[0] if door else next(given))
        return out

    def _metres(self, cells: list[tuple[int, int]]) -> list[Waypoint]:
        world = self.spec.cell_to_world(np.asarray(cells, dtype=np.float64).reshape(-1, 2))
        return [(float(x), float(y)) for x, y in np.round(world, 9)]

    def _keep_changes(self, observation: Observation) -> None:
        """Hold the cells `observation` changed for the inner planner's next decision (None: all)."""
        if observation.changed is None:
            self._unseen = None
        elif self._unseen is not None:
            self._unseen.append(observation.changed)

    def _with_kept_changes(self, observation: Observation) -> Observation:
        """`observation` with the changes of the decisions the inner planner did not see folded in."""
        unseen, self._unseen = self._unseen, []
        if unseen is not None and not unseen:
            return observation
        changed = (
            None
            if unseen is None or observation.changed is None
            else np.unique(np.concatenate([*unseen, observation.changed]))
        )
        return Observation(observation.belief, observation.position, observation.cell, changed, observation.step)
