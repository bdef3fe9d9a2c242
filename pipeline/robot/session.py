"""An exploration session: any planner of ours on a robot's live SLAM map and pose.

    session = ExplorationSession(planner="guide", protocol="real_robot")
    session.update_map(msg)          # a nav_msgs/OccupancyGrid (rclpy's, rosbags', or anything with its fields)
    session.update_pose(x, y, yaw)   # the robot in the map frame, metres (from tf: map -> base_link)
    plan = session.plan()            # plan.waypoints: the next waypoints in the map frame; plan.done
    session.goal_failed(x, y)        # the navigation stack could not reach that waypoint
    session.save_map("maps/run_1.yaml")  # the belief as a ROS map: `guide plans import` takes it

Inside, the belief lives on a grid of the protocol's cell size whose lattice is anchored at the
first pose (`Canvas`); it grows by whole lattice steps as the SLAM map grows or its origin moves,
and keeps what was seen where a later map says nothing. The planner is reset from that grid's
frame (never a ground truth) and again whenever the grid grows. The robot, which stands anywhere,
is snapped to the nearest known-free lattice node it can reach in a straight known-free line
(under the door-aware graph only when that node is within `goal_tolerance_m`: elsewhere it plans
from its own cell, as a door node or a frontier the lattice misses leaves it).
A failed goal's node is no longer a target (it counts as visited); failed again soon after, it is
marked occupied (its own cell only) for the next AVOID_PLANS plans, so that no plan stands on it
meanwhile, then tried again, as a navigation stack's failures often pass. `plan()`
plans afresh when the robot has reached its waypoint, when the map has changed by
`replan_changed_cells` cells, after `replan_after_s` seconds, or when asked (`force`); otherwise it
returns the plan it made last. Bad input (a NaN pose, a pose off the map, an empty map, data of
the wrong length, values outside -1..100) is logged and skipped: the session goes on.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, cast

import numpy as np

from pipeline.planners import make_planner
from pipeline.planners.wrapper import innermost
from pipeline.robot.occupancy_grid import BadMessage, Canvas, Grid, read_grid, write_belief_map
from pipeline.world.geometry import segment_is_known_free
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation, Planner
from pipeline.world.protocol import PROTOCOLS, Protocol
from pipeline.world.sensor import FREE, OCCUPIED
from pipeline.world.simulator import PLANNER_DECISION

log = logging.getLogger("guide.robot")

SNAP_NODES = 3  # the robot is snapped to a node at most this many lattice steps away
OWN_CELL_REACH = 2  # under the door-aware graph, the robot's cell is the known-free one at most this many cells away
AVOID_PLANS = 10  # a goal failed twice is blocked for this many plans, then tried again (failures pass)
GROWTH_MARGIN_RANGES = 2.0  # the belief grows this many lidar ranges past a map that leaves it
MAX_CANVAS_CELLS = 16_000_000  # the belief grid's largest size (800 m x 800 m at 0.2 m): a larger map is refused


@dataclass(frozen=True)
class Plan:
    """One decision: `waypoints` (map frame, metres) to drive to in order, `done` when nothing
    reachable is left to explore, the node the planner heads for (`target`, map frame; None when it
    does not say), the time it took (`decision_ms`, conversion of the map included) and why it was
    made or kept (`reason`)."""

    waypoints: list[tuple[float, float]] = field(default_factory=list)
    done: bool = False
    target: tuple[float, float] | None = None
    decision_ms: float = 0.0
    reason: str = ""
    replanned: bool = False
    fallback: bool = False  # the planner's own rule found nothing: these go to the nearest reachable frontier


@dataclass
class SessionState:
    """What the session holds, for logs and recordings."""

    maps_used: int = 0
    maps_skipped: int = 0
    poses_skipped: int = 0
    plans: int = 0
    resets: int = 0
    failed_goals: list[tuple[float, float]] = field(default_factory=list)
    last_skip: str = ""
    # The planner's record of its checked predictions after the last plan (right, wrong, base,
    # lift, trust: prediction/prediction_trust.py); None for a planner that keeps none.
    prediction_trust: dict[str, float | int] | None = None
    # Plans that were not the planner's own rule (pipeline/planners/whole_building.py): its
    # nearest-frontier fallback, and the way back to the lattice after one.
    fallbacks: int = 0


class ExplorationSession:
    """A planner (by its registered name, with options) exploring from live maps and poses."""

    def __init__(
        self,
        planner: str | Planner = "guide",
        protocol: Protocol | str = "real_robot",
        *,
        planner_options: dict[str, Any] | None = None,
        seed: int = 0,
        goal_tolerance_m: float = 0.5,
        replan_changed_cells: int = 50,
        replan_after_s: float = 5.0,
        clock=time.monotonic,
    ) -> None:
        self.protocol = resolve_protocol(protocol)
        self.planner = planner if isinstance(planner, Planner) else make_planner(planner, **(planner_options or {}))
        self.seed = int(seed)
        self.goal_tolerance_m = float(goal_tolerance_m)
        self.replan_changed_cells = int(replan_changed_cells)
        self.replan_after_s = float(replan_after_s)
        self.clock = clock
        self.step_cells = lattice_step_cells(self.protocol)
        self.canvas: Canvas | None = None
        self.pending: Grid | None = None  # a map that came before the first pose
        self.pose: tuple[float, float, float] | None = None
        self.state = SessionState()
        self.blocked: list[tuple[float, float, int]] = []  # goals failed twice (map frame), blocked until that plan
        self.avoided: list[tuple[float, float]] = []  # failed goals (map frame): no longer targets
        self.recent_failures: list[tuple[float, float, int]] = []  # (x, y, the plan count when it failed)
        self._planned_belief: np.ndarray | None = None  # the belief the planner saw last
        self._frame: MapFrame | None = None
        self._last: Plan | None = None
        self._last_time = -math.inf
        self._changed_since = 0

    # ------------------------------------------------------------------ input
    def update_map(self, msg: Any) -> bool:
        """Take a map message; False (logged) when it is skipped."""
        try:
            grid = read_grid(msg)
        except BadMessage as error:
            return self._skip_map(str(error))
        if self.canvas is None:
            self.pending = grid
            if self.pose is not None:
                self._anchor(self.pose)
            return True
        if not self._fits(grid):
            return self._skip_map(
                f"its extent {_extent_text(grid.extent)} would grow the belief past {MAX_CANVAS_CELLS:,} cells"
            )
        if not self.canvas.contains(grid.extent):  # grown with room to spare: each growth rebuilds the planner
            self.canvas.cover(grid.extent, margin_m=GROWTH_MARGIN_RANGES * self.protocol.sensor_range)
        before = self.canvas.belief.copy() if self._planned_belief is not None else None
        self.canvas.paint(grid)
        if before is not None and before.shape == self.canvas.belief.shape:
            self._changed_since += int(np.count_nonzero(before != self.canvas.belief))
        else:
            self._changed_since += self.replan_changed_cells
        self.state.maps_used += 1
        return True

    def update_pose(self, x: float, y: float, yaw: float = 0.0) -> bool:
        """Take the robot's pose in the map frame (metres, radians); False (logged) when skipped."""
        try:
            x, y, yaw = float(x), float(y), float(yaw)
        except (TypeError, ValueError):
            return self._skip_pose(f"pose must be numbers, got ({x!r}, {y!r}, {yaw!r})")
        if not (math.isfinite(x) and math.isfinite(y) and math.isfinite(yaw)):
            return self._skip_pose(f"pose must be finite, got ({x}, {y}, {yaw})")
        if self.canvas is None:
            if self.pending is not None and not _inside(self.pending.extent, x, y):
                return self._skip_pose(
                    f"pose ({x:.2f}, {y:.2f}) lies outside the map {_extent_text(self.pending.extent)}"
                )
            self.pose = (x, y, yaw)
            if self.pending is not None:
                self._anchor(self.pose)
            return True
        else:
            col, row = self.canvas.to_cell(x, y)
            rows, cols = self.canvas.belief.shape
            if not (0 <= col < cols and 0 <= row < rows):
                return self._skip_pose(f"pose ({x:.2f}, {y:.2f}) lies outside the map")
        self.pose = (x, y, yaw)
        return True

    def _anchor(self, pose: tuple[float, float, float]) -> None:
        """The belief grid, its lattice anchored at `pose`, with the map that came first painted on."""
        grid = cast(Grid, self.pending)  # a map came before the pose
        x, y = pose[:2]
        if not _inside(grid.extent, x, y):
            self.pose = None  # a pose is only kept once it lies on a map
            return
        radius = self.protocol.robot_radius_m if self.protocol.uses_door_graph else 0.0
        canvas = Canvas(self.protocol.cell_size, self.step_cells, (x, y), robot_radius_m=radius)
        # At least a lidar's reach around the start: the first scans fit, and the predictor sees a whole image.
        canvas.cover((x, y, x, y), margin_m=self.protocol.sensor_range + self.protocol.node_resolution)
        self.canvas = canvas
        if not self._fits(grid):
            self.canvas, self.pending = None, None
            self._skip_map(
                f"its extent {_extent_text(grid.extent)} would make the belief larger than {MAX_CANVAS_CELLS:,} cells"
            )
            return
        self.pending = None
        canvas.cover(grid.extent)
        canvas.paint(grid)
        self.state.maps_used += 1

    def _fits(self, grid: Grid) -> bool:
        """Whether the belief grid, grown to cover `grid`, stays within MAX_CANVAS_CELLS."""
        x0, y0, x1, y1 = grid.extent
        ox, oy = self._grid.origin
        rows, cols = self._grid.belief.shape
        c = self.protocol.cell_size
        width = (max(x1, ox + cols * c) - min(x0, ox)) / c
        height = (max(y1, oy + rows * c) - min(y0, oy)) / c
        return width * height <= MAX_CANVAS_CELLS

    def goal_failed(self, x: float, y: float) -> None:
        """The navigation stack could not reach (x, y): its lattice node is no longer a target; failed
        again soon after, the node is blocked for AVOID_PLANS plans."""
        if self.canvas is None or not (math.isfinite(float(x)) and math.isfinite(float(y))):
            return
        x, y = float(x), float(y)
        node = self._node_cell(self.canvas.to_world(x, y))
        recent = [(fx, fy) for fx, fy, plan in self.recent_failures if plan > self.state.plans - AVOID_PLANS]
        if any(self._node_cell(self.canvas.to_world(fx, fy)) == node for fx, fy in recent):
            self.blocked.append((x, y, self.state.plans + AVOID_PLANS))
            log.info("goal (%.2f, %.2f) failed again: its node is blocked for %d plans", x, y, AVOID_PLANS)
        else:
            self.avoided.append((x, y))
            log.info("goal (%.2f, %.2f) failed: its node is no longer a target", x, y)
        self.recent_failures.append((x, y, self.state.plans))
        self.state.failed_goals.append((x, y))
        self._changed_since += self.replan_changed_cells  # plan afresh

    def save_map(self, path: str | Path) -> Path:
        """Write the belief as a ROS map_server map: `path` (a .yaml, or a folder that gets
        `map.yaml`) with its trinary PGM beside it (free 254, occupied 0, unknown 205) and a `start`
        key at the first pose, in the map frame. `guide plans import` takes it, so that a robot's own
        runs become training data. The YAML's path; ValueError before the first map and pose."""
        if self.canvas is None:
            raise ValueError("no map to save yet: the session needs a map and a pose first")
        path = Path(path)
        if path.suffix.lower() not in (".yaml", ".yml"):
            path = path / "map.yaml"
        path.parent.mkdir(parents=True, exist_ok=True)
        write_belief_map(self.canvas.belief, self.protocol.cell_size, self.canvas.origin, self.canvas.anchor, path)
        return path

    # ------------------------------------------------------------------ decisions
    def plan(self, force: bool = False) -> Plan:
        """The next waypoints: planned afresh when due (see the module's docstring), else the last plan."""
        started = time.perf_counter()
        if self.canvas is None or self.pose is None or self.state.maps_used == 0:
            return Plan(reason="waiting for a map and a pose")
        reason = self._replan_reason(force)
        if reason is None:
            return replace(cast(Plan, self._last), replanned=False, reason="kept")
        belief = self._belief()
        robot = self._snap(belief)
        if robot is None:
            return self._keep(Plan(reason="the robot is not near known free space", decision_ms=_ms(started)))
        frame = MapFrame(belief.shape, self.protocol.cell_size, self.canvas.start_cell, "robot")
        changed = None
        if frame == self._frame and self._planned_belief is not None:
            before = self._planned_belief.reshape(-1)
            changed = np.flatnonzero(before != belief.reshape(-1))
            if np.any(before[changed] == FREE):
                changed = None  # a known-free cell is free no longer (SLAM revised it, a goal failed): start afresh
        if changed is None:
            # The planners' lattice graphs only ever gain known-free edges, as a simulated belief only
            # ever gains known cells: a grown grid or a lost free cell needs a graph built anew.
            self._reset_planner(frame)
        world, cell = robot
        self._mark_avoided()
        observation = Observation(belief=belief, position=world, cell=cell, changed=changed, step=self.state.plans)
        waypoints = self.planner.plan(observation)
        if not waypoints and (self.blocked or self.avoided):  # done only if nothing is left with every goal allowed
            avoided = self.avoided
            self.blocked, self.avoided = [], []
            belief = self._belief()
            self._reset_planner(frame)
            graph, marks = self._graph_and_visits()
            for x, y in avoided if graph is not None and marks is not None else ():
                marks[graph.nearest_node(self._grid.to_world(x, y))] = False  # targets again
            waypoints = self.planner.plan(replace(observation, belief=belief, changed=None))
        self._planned_belief = belief
        self._changed_since = 0
        self._last_time = self.clock()
        self.state.plans += 1
        trust = getattr(self.planner, "trust_state", None)
        self.state.prediction_trust = trust.as_dict() if trust is not None else None
        fallback = getattr(self.planner, "decision_kind", PLANNER_DECISION) not in (PLANNER_DECISION, "done")
        self.state.fallbacks += int(fallback)
        decision = getattr(self.planner, "last_decision", {}) or {}
        target = self._target(decision.get("target"), waypoints)
        plan = Plan(
            [self._grid.to_map(w) for w in waypoints],
            done=not waypoints,
            target=target,
            decision_ms=_ms(started),
            reason=reason,
            replanned=True,
            fallback=fallback,
        )
        return self._keep(plan)

    def _reset_planner(self, frame: MapFrame) -> None:
        """Reset the planner on `frame`, keeping the nodes it had visited (in the map frame): a
        planner does not go back to see again what it saw from there."""
        visited = self._visited_points()
        trust = getattr(
            self.planner, "trust_state", None
        )  # the same building: what was learnt of the predictions holds
        self.planner.reset(frame, self.protocol, self.seed)
        if trust is not None:
            cast(Any, self.planner).restore_trust(trust)
        self._frame = frame
        self.state.resets += 1
        graph, marks = self._graph_and_visits()
        if graph is not None and marks is not None and len(visited):
            d = self.protocol.node_resolution
            for x, y in visited:
                i, j = round(x / d), round(y / d)
                node = graph.node_id(i, j)
                if node >= 0:
                    marks[node] = True

    def _graph_and_visits(self) -> tuple[Any, Any]:
        """The planner's lattice graph and its visited marks (None, None for a planner without them)."""
        base = innermost(self.planner)
        graph, marks = getattr(base, "graph", None), getattr(base, "visited", None)
        return (graph, marks) if graph is not None and marks is not None else (None, None)

    def _mark_avoided(self) -> None:
        """The failed goals' nodes marked visited: a planner heads for no visited node."""
        graph, marks = self._graph_and_visits()
        if graph is None or marks is None:
            return
        for x, y in self.avoided:
            marks[graph.nearest_node(self._grid.to_world(x, y))] = True

    def _visited_points(self) -> list[tuple[float, float]]:
        """The planner's visited nodes as planner positions of the current frame's anchor (which
        every frame keeps)."""
        graph, marks = self._graph_and_visits()
        if graph is None or marks is None or self._frame is None:
            return []
        return [tuple(xy) for xy in graph.node_world[np.flatnonzero(marks)]]

    @property
    def _grid(self) -> Canvas:
        """The belief grid, there once a map and a pose came (its readers run after)."""
        return cast(Canvas, self.canvas)

    @property
    def _pose(self) -> tuple[float, float, float]:
        """The robot's pose, there once one came (its readers run after)."""
        return cast(tuple[float, float, float], self.pose)

    def _replan_reason(self, force: bool) -> str | None:
        last = self._last
        if force:
            return "asked"
        if last is None or not last.replanned:
            return "first plan" if last is None else "no plan yet"
        if last.done:
            return "map changed" if self._changed_since else None
        if last.waypoints and math.dist(self._pose[:2], last.waypoints[0]) <= self.goal_tolerance_m:
            return "waypoint reached"
        if self._changed_since >= self.replan_changed_cells:
            return "map changed"
        if self.clock() - self._last_time >= self.replan_after_s:
            return "timeout"
        return None

    def _keep(self, plan: Plan) -> Plan:
        self._last = plan
        return plan

    def _belief(self) -> np.ndarray:
        """The canvas's belief with every failed goal's node marked occupied."""
        belief = self._grid.belief.copy()
        rows, cols = belief.shape
        self.blocked = [goal for goal in self.blocked if goal[2] > self.state.plans]
        for x, y, _ in self.blocked:  # the node's own cell: no plan stands on it, the corridor around stays open
            col, row = self._node_cell(self._grid.to_world(x, y))
            if 0 <= col < cols and 0 <= row < rows:
                belief[row, col] = OCCUPIED
        return belief

    def _node_cell(self, world: tuple[float, float]) -> tuple[int, int]:
        """The canvas cell of the lattice node nearest a planner position."""
        d = self.protocol.node_resolution
        i, j = round(world[0] / d), round(world[1] / d)
        return (
            self._grid.start_cell[0] + int(round(i * self.step_cells)),
            self._grid.start_cell[1] + int(round(j * self.step_cells)),
        )

    def _snap(self, belief: np.ndarray) -> tuple[tuple[float, float], tuple[int, int]] | None:
        """(planner position, cell) of the nearest known-free lattice node the robot reaches in a
        straight known-free line (else the nearest known-free one); None when none is near. Under
        the door-aware graph a robot farther than `goal_tolerance_m` from that node (at a door node,
        on its way to a frontier the lattice does not reach) stands where it is: its own cell, or
        the nearest known-free cell beside it."""
        world = self._grid.to_world(*self._pose[:2])
        d = self.protocol.node_resolution
        here = self._grid.to_cell(*self._pose[:2])
        free = belief == FREE
        rows, cols = belief.shape
        i0, j0 = round(world[0] / d), round(world[1] / d)
        candidates = []
        for di in range(-SNAP_NODES, SNAP_NODES + 1):
            for dj in range(-SNAP_NODES, SNAP_NODES + 1):
                col = self._grid.start_cell[0] + (i0 + di) * self.step_cells
                row = self._grid.start_cell[1] + (j0 + dj) * self.step_cells
                if 0 <= col < cols and 0 <= row < rows and free[row, col]:
                    node = ((i0 + di) * d, (j0 + dj) * d)
                    candidates.append((math.dist(node, world), node, (col, row)))
        candidates.sort()
        inside = 0 <= here[0] < cols and 0 <= here[1] < rows
        straight = next(
            ((gap, node, cell) for gap, node, cell in candidates if inside and segment_is_known_free(free, here, cell)),
            None,
        )
        if self.protocol.uses_door_graph and (straight is None or straight[0] > self.goal_tolerance_m):
            own = self._own_cell(free, here)
            if own is not None:
                return own
        if straight is not None:
            return straight[1], straight[2]
        return (candidates[0][1], candidates[0][2]) if candidates else None

    def _own_cell(self, free: np.ndarray, here: tuple[int, int]) -> tuple[tuple[float, float], tuple[int, int]] | None:
        """(planner position, cell) of the known-free cell nearest the robot's own, at most
        OWN_CELL_REACH cells away; None when there is none."""
        rows, cols = free.shape
        best = None
        for dr in range(-OWN_CELL_REACH, OWN_CELL_REACH + 1):
            for dc in range(-OWN_CELL_REACH, OWN_CELL_REACH + 1):
                col, row = here[0] + dc, here[1] + dr
                if (
                    0 <= col < cols
                    and 0 <= row < rows
                    and free[row, col]
                    and (best is None or dc * dc + dr * dr < best[0])
                ):
                    best = (dc * dc + dr * dr, (col, row))
        if best is None:
            return None
        col, row = best[1]
        c = self.protocol.cell_size
        return ((col - self._grid.start_cell[0]) * c, (row - self._grid.start_cell[1]) * c), (col, row)

    def _target(self, node: Any, waypoints: list) -> tuple[float, float] | None:
        graph = getattr(innermost(self.planner), "graph", None)
        if node is not None and graph is not None:
            try:
                return self._grid.to_map(tuple(graph.node_world[int(node)]))
            except (IndexError, TypeError, ValueError):
                pass
        return self._grid.to_map(waypoints[-1]) if waypoints else None

    def _skip_map(self, why: str) -> bool:
        self.state.maps_skipped += 1
        self.state.last_skip = f"map skipped: {why}"
        log.warning("map skipped: %s", why)
        return False

    def _skip_pose(self, why: str) -> bool:
        self.state.poses_skipped += 1
        self.state.last_skip = f"pose skipped: {why}"
        log.warning("pose skipped: %s", why)
        return False


def _inside(extent: tuple[float, float, float, float], x: float, y: float) -> bool:
    return extent[0] <= x <= extent[2] and extent[1] <= y <= extent[3]


def _extent_text(extent: tuple[float, float, float, float]) -> str:
    return f"({extent[0]:.1f}, {extent[1]:.1f})-({extent[2]:.1f}, {extent[3]:.1f}) m"


def resolve_protocol(protocol: Protocol | str) -> Protocol:
    """A Protocol, or the name of a shipped profile's ("maze", "real_robot")."""
    if isinstance(protocol, Protocol):
        return protocol
    if isinstance(protocol, str) and protocol in PROTOCOLS:
        return PROTOCOLS[protocol]
    raise ValueError(f"protocol must be a Protocol or one of {', '.join(PROTOCOLS)}, got {protocol!r}")


def lattice_step_cells(protocol: Protocol) -> int:
    """The lattice spacing in cells; ValueError when the node spacing is not a whole number of cells
    (the lattice could not keep its place as the map grows)."""
    step = protocol.node_resolution / protocol.cell_size
    if abs(step - round(step)) > 1e-6 or round(step) < 1:
        raise ValueError(
            f"node_resolution ({protocol.node_resolution:g} m) must be a whole number of cells "
            f"({protocol.cell_size:g} m) for a robot session"
        )
    return int(round(step))


def _ms(started: float) -> float:
    return (time.perf_counter() - started) * 1e3
