"""Episodes under the benchmark protocol, for one robot or a team: sensing, the motion rule, the done
rule, and the event loop that runs them. A single robot is a team of one.

The episode is the referee: planners only propose waypoints, and every waypoint is checked here
(`waypoint_cell`; its segment known-free in its robot's belief when the robot departs), so no
planner can claim a distance the protocol would not allow.

Every robot has the protocol's lidar and motion rule and the same speed, so time is counted in
metres of travel. Events run in time order: the robot that arrives next senses, the beliefs
update, and that robot decides when its plan is used up; one that finds nothing to do waits and
asks again after the next arrival (a teammate may open new frontier). With full communication
(`comm_range_m` None) the robots hold one belief. With a range, each robot holds its own; robots
within `comm_range_m` of each other, or linked through a chain of robots that are, merge theirs at
every event (positions of robots on the way are interpolated along their segment). The done rule
applies to the union of all beliefs.
"""

from __future__ import annotations

import heapq
import math
import time
from typing import Any, Callable, Sequence, TypeVar, cast

import numpy as np

from pipeline.world.geometry import segment_is_known_free
from pipeline.world.maps import GroundTruthMap, MapFrame
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN, Belief, Lidar
from pipeline.world.team_files import MAX_ROBOTS

LATTICE_TOLERANCE_M = 1e-3
IDLE = "idle"  # `run_events`: every robot waited with nothing to do
MOVE_LIMIT = "move limit"  # `run_events`: a robot made `max_steps` moves
MOTION_RULE = "motion rule"  # `run_events`: the start of the ending of a waypoint the motion rule refused


class MotionError(Exception):
    """A waypoint that breaks the motion rule; the planner is in error."""


def waypoint_cell(
    world: GroundTruthMap | MapFrame, protocol: Protocol, waypoint: Sequence[float]
) -> tuple[tuple[int, int], Waypoint]:
    """(the cell, the exact position in metres) of a waypoint: a lattice node inside the grid, or,
    under the door-aware graph (`Protocol.uses_door_graph`), any cell's centre (a door node, or a
    cell on the way to a frontier the lattice does not reach). MotionError for any other point."""
    x, y = float(waypoint[0]), float(waypoint[1])
    if not (np.isfinite(x) and np.isfinite(y)):
        raise MotionError(f"waypoint ({x}, {y}) is not finite")
    d, size, start = protocol.node_resolution, protocol.cell_size, world.start_cell
    i, j = round(x / d), round(y / d)
    if abs(i * d - x) <= LATTICE_TOLERANCE_M and abs(j * d - y) <= LATTICE_TOLERANCE_M:
        position = (i * d, j * d)
        col, row = start[0] + int(round(i * d / size)), start[1] + int(round(j * d / size))
    else:
        ci, cj = round(x / size), round(y / size)
        door = protocol.uses_door_graph
        if not door or abs(ci * size - x) > LATTICE_TOLERANCE_M or abs(cj * size - y) > LATTICE_TOLERANCE_M:
            where = "a cell centre" if door else f"on the {d} m node lattice"
            raise MotionError(f"waypoint ({x:.3f}, {y:.3f}) is not {where}")
        position = (ci * size, cj * size)
        col, row = start[0] + ci, start[1] + cj
    rows, cols = world.shape
    if not (0 <= col < cols and 0 <= row < rows):
        raise MotionError(f"waypoint ({x:.3f}, {y:.3f}) lies outside the map")
    return (col, row), position


class Robot:
    """One robot's state in the event loop."""

    def __init__(self, index: int, position: Waypoint, cell: tuple[int, int]):
        self.index = index
        self.position, self.cell = position, cell
        self.clock = 0.0  # time of its next event: arrival at `heading`, or its next decision
        self.departed_at = 0.0
        self.origin = position  # where the move under way started
        self.heading: tuple[Waypoint, tuple[int, int]] | None = None  # (waypoint, cell) of the move under way
        self.plan: list[Sequence[float]] = []  # the waypoints of its plan still to drive, as planned
        self.target: Waypoint | None = None
        self.waiting = False  # planned nothing: asks again after the next arrival
        self.stopped = False  # made max_steps moves: stays where it is
        self.moves = 0
        self.travelled = 0.0  # finished moves
        self.pending: list[np.ndarray] = []  # cells changed in its belief since its last decision
        self.first = True
        # Per row of its trajectory (the start first): where, distance so far, its belief's free cells.
        self.trajectory: list[Waypoint] = [position]
        self.distances: list[float] = [0.0]
        self.explored: list[int] = []

    def location(self, t: float) -> Waypoint:
        """Where it is at time t (on its segment while it moves)."""
        if self.heading is None:
            return self.position
        (x1, y1), (x0, y0) = self.heading[0], self.origin
        length = math.hypot(x1 - x0, y1 - y0)
        share = 1.0 if length == 0 else min(1.0, max(0.0, (t - self.departed_at) / length))
        return (x0 + share * (x1 - x0), y0 + share * (y1 - y0))


class EpisodeState:
    """1 to MAX_ROBOTS robots on one map: beliefs, positions, clocks and the protocol's rules, in
    time order. `Episode` (one robot) and `TeamEpisode` are its two faces."""

    names_robots = False  # whether a motion-rule message names its robot (a team's do)

    # A segment's length: numpy's for the single robot, `math.hypot` for a team (they can differ in
    # the last bit), so that each face's distances reproduce bit for bit.
    _length: staticmethod[[float, float], float] = staticmethod(lambda dx, dy: float(np.hypot(dx, dy)))

    def __init__(
        self,
        ground_truth: GroundTruthMap,
        protocol: Protocol,
        robots: int = 1,
        starts: Sequence[Sequence[float]] | None = None,
        comm_range_m: float | None = None,
    ):
        if not 1 <= int(robots) <= MAX_ROBOTS:
            raise ValueError(f"robots must be 1-{MAX_ROBOTS}, got {robots}")
        if comm_range_m is not None and not (math.isfinite(comm_range_m) and comm_range_m > 0):
            raise ValueError(f"comm_range_m must be a positive number of metres, got {comm_range_m}")
        points = (
            [(0.0, 0.0)] * robots if starts is None else cast(list[Waypoint], [tuple(map(float, s)) for s in starts])
        )
        if len(points) != robots:
            raise ValueError(f"{len(points)} starts given for {robots} robots")
        placed = []
        for k, point in enumerate(points):
            cell, position = waypoint_cell(ground_truth, protocol, point)
            if not ground_truth.free[cell[1], cell[0]]:
                raise ValueError(f"start of robot {k} ({point[0]:g}, {point[1]:g}) is not a free cell")
            placed.append(Robot(k, position, cell))
        self._setup(ground_truth, protocol, placed, comm_range_m)
        for robot in self.robots:
            self._sense(robot)
        self._communicate()
        self._record()

    def _setup(
        self, ground_truth: GroundTruthMap, protocol: Protocol, robots: list[Robot], comm_range_m: float | None
    ) -> None:
        """Every field of a fresh episode of `robots` before anyone senses."""
        n = len(robots)
        self.map, self.protocol, self.comm_range_m = ground_truth, protocol, comm_range_m
        self.lidar = Lidar(ground_truth.free, protocol.sensor_range_cells)
        self.robots = robots
        one = Belief(ground_truth.shape)
        self.beliefs = [one] * n if self.shared else [Belief(ground_truth.shape) for _ in range(n)]
        self.union = one if self.shared else Belief(ground_truth.shape)
        # What each robot last heard of each teammate: position and target (its own: always current).
        self.heard_positions = [[r.position for r in robots] for _ in robots]
        self.heard_targets: list[list[Waypoint | None]] = [[None] * n for _ in robots]
        self.connected = [[True] * n for _ in robots]
        self.time = 0.0
        self.rows: list[tuple[float, int, float, float]] = [(0.0, r.index, *r.position) for r in robots]
        self.coverage: list[tuple[float, float]] = []  # (time, explored share of the union) after every event
        self.merges: list[tuple[float, tuple[int, ...]]] = []
        self.completion_time: float | None = None
        self.completed_after: list[int] = []  # each robot's trajectory rows when the episode was done

    # -- beliefs ------------------------------------------------------------------------------
    @property
    def shared(self) -> bool:
        return self.comm_range_m is None

    @property
    def unknown_free_cells(self) -> int:
        return self.map.free_cell_count - self.union.free_count

    @property
    def complete(self) -> bool:
        return self.completion_time is not None

    @property
    def explored_ratio(self) -> float:
        return self.union.free_count / max(1, self.map.free_cell_count)

    def _sense(self, robot: Robot) -> None:
        result = self.lidar.scan(robot.cell)
        belief = self.beliefs[robot.index]
        changed = belief.apply(result)
        if changed.size:
            for other in self.robots if self.shared else [robot]:
                other.pending.append(changed)
        if not self.shared:
            self.union.apply(result)
        robot.explored.append(belief.free_count)

    def groups(self) -> list[list[int]]:
        """The robots linked by communication now: all of them with full communication; else the
        connected groups of the within-range graph (positions interpolated on the way)."""
        if self.shared:
            return [list(range(len(self.robots)))]
        from scipy.sparse.csgraph import connected_components  # only ranges need it

        where = np.array([r.location(self.time) for r in self.robots])
        near = np.hypot(*(where[:, None, :] - where[None, :, :]).transpose(2, 0, 1)) <= self.comm_range_m
        count, labels = connected_components(near, directed=False)
        return [np.flatnonzero(labels == c).tolist() for c in range(count)]  # by their lowest robot

    def _communicate(self) -> None:
        """Merge the beliefs of every linked group and pass on positions and targets."""
        for group in self.groups():
            members = [self.robots[k] for k in group]
            for robot in members:
                for k in range(len(self.robots)):
                    self.connected[robot.index][k] = k in group
                for other in members:
                    self.heard_positions[robot.index][other.index] = other.location(self.time)
                    self.heard_targets[robot.index][other.index] = other.target
            if self.shared or len(group) == 1:
                continue
            grids = np.stack([self.beliefs[k].grid for k in group])
            merged = np.full(grids.shape[1:], UNKNOWN, dtype=np.uint8)
            merged[(grids == OCCUPIED).any(axis=0)] = OCCUPIED
            merged[(grids == FREE).any(axis=0)] = FREE
            gained = False
            for robot in members:
                belief = self.beliefs[robot.index]
                changed = np.flatnonzero(belief.grid != merged)
                if changed.size:
                    gained = True
                    belief.grid[...] = merged
                    belief.free_count = int((merged == FREE).sum())
                    robot.pending.append(changed)
            if gained:
                self.merges.append((self.time, tuple(group)))

    def _record(self) -> None:
        if self.completion_time is None and self.unknown_free_cells <= self.protocol.done_unknown_cells:
            self.completion_time = self.time
            self.completed_after = [len(r.trajectory) for r in self.robots]
        self.coverage.append((self.time, self.explored_ratio))

    # -- one robot ----------------------------------------------------------------------------
    def observe(self, robot: int = 0) -> Observation:
        """Robot `robot`'s own view before it decides (a team's `TeamEpisode.observe` adds what it
        knows of its teammates); its pending changes are handed over."""
        r = self.robots[robot]
        if r.first:
            changed, r.first = None, False
        elif r.pending:
            changed = np.unique(np.concatenate(r.pending))
        else:
            changed = np.zeros(0, dtype=np.int64)
        r.pending = []
        return Observation(self.beliefs[robot].grid, r.position, r.cell, changed, r.moves)

    def depart(self, robot: int, waypoint: Sequence[float], oracle: bool = False) -> None:
        """Start robot `robot`'s move to a waypoint (`waypoint_cell`): known-free in its belief now
        (with `oracle`, the ground-truth reference's rule: free in the ground truth)."""
        r = self.robots[robot]
        cell, target = waypoint_cell(self.map, self.protocol, waypoint)
        free = self.map.free if oracle else self.beliefs[robot].grid == FREE
        if not segment_is_known_free(free, r.cell, cell):
            what = "ground-truth free" if oracle else "known to be free"
            who = f"robot {robot}: " if self.names_robots else ""
            raise MotionError(
                f"{who}segment ({r.position[0]:.3f}, {r.position[1]:.3f}) -> "
                f"({float(waypoint[0]):.3f}, {float(waypoint[1]):.3f}) crosses cells not {what}"
            )
        r.origin, r.departed_at = r.position, self.time
        r.heading = (target, cell)
        r.clock = self.time + self._length(target[0] - r.position[0], target[1] - r.position[1])

    def arrive(self, robot: int) -> None:
        """Robot `robot` reaches the end of its move: it senses there and the beliefs update."""
        r = self.robots[robot]
        (target, cell), r.heading = cast(tuple[Waypoint, tuple[int, int]], r.heading), None
        r.travelled += self._length(target[0] - r.origin[0], target[1] - r.origin[1])
        r.position, r.cell = target, cell
        r.moves += 1
        r.trajectory.append(target)
        r.distances.append(r.travelled)
        self.rows.append((self.time, robot, *target))
        self._sense(r)

    def advance(self, robot: int, t: float) -> None:
        """Robot `robot`'s event at time `t`: it arrives if it was moving, linked robots merge what
        they know, and the done rule is checked."""
        self.time = t
        if self.robots[robot].heading is not None:
            self.arrive(robot)
        self._communicate()
        self._record()


class EventLoop:
    """An episode's events in time order, between its decisions: `next_decision` runs them until a
    robot's plan is used up and returns that robot; `decide` hands it its plan. `run_events` puts a
    planner between the two; an environment puts its agents' actions there.

    Events are (time, waiting, robot): at one time, arrivals and decisions come before the retries
    of waiting robots, and lower robot numbers first."""

    def __init__(self, episode: EpisodeState, oracle: bool = False):
        self.episode, self.oracle = episode, oracle
        self.queue = [(0.0, 0, r.index) for r in episode.robots]
        heapq.heapify(self.queue)
        self.ending: str | None = None  # once over: "" (done), IDLE, MOVE_LIMIT or "motion rule: ..."

    def next_decision(self, on_event: Callable[[int], None] | None = None) -> int | None:
        """Run events until a robot must decide (its number) or the episode is over (None, with
        `ending` set). `on_event` receives the robot of each event, after the beliefs update."""
        episode, queue = self.episode, self.queue
        while self.ending is None and queue and not episode.complete:
            t, _, index = heapq.heappop(queue)
            robot = episode.robots[index]
            episode.advance(index, t)
            if on_event is not None:
                on_event(index)
            if episode.complete:
                break
            if robot.moves >= episode.protocol.max_steps:
                robot.stopped, robot.target = True, None  # it stays where it is for the rest of the episode
                continue
            if not robot.plan:
                return index
            self._depart(index)
        if self.ending is None:
            stopped = any(r.stopped for r in episode.robots)
            self.ending = "" if episode.complete else MOVE_LIMIT if stopped else IDLE
        return None

    def decide(self, index: int, plan: Sequence[Sequence[float]]) -> None:
        """Robot `index`'s plan: it departs on its first waypoint, or, with none, waits and asks
        again after the next arrival (the episode ends IDLE when nobody moves or is left to decide)."""
        episode = self.episode
        robot = episode.robots[index]
        robot.plan = list(plan)
        robot.target = cast(Waypoint, tuple(map(float, robot.plan[-1]))) if robot.plan else None
        episode.heard_targets[index][index] = robot.target
        if robot.plan:
            self._depart(index)
            return
        robot.waiting = True
        moving = [r.clock for r in episode.robots if r.heading is not None]
        if moving:
            heapq.heappush(self.queue, (min(moving), 1, index))
        elif not self.queue:  # nobody moves and nobody is left to decide
            self.ending = IDLE
        # else another robot decides at this time: if it moves, this one asks again

    def _depart(self, index: int) -> None:
        """Robot `index` starts the next move of its plan; waiting robots with nobody moving ask again."""
        robot = self.episode.robots[index]
        robot.waiting = False
        try:
            self.episode.depart(index, robot.plan.pop(0), self.oracle)
        except MotionError as error:
            self.ending = f"{MOTION_RULE}: {error}"
            return
        heapq.heappush(self.queue, (robot.clock, 0, index))
        for other in self.episode.robots:  # a robot waiting with nobody moving asks again now that one is
            if other.waiting and not other.stopped and not any(e[2] == other.index for e in self.queue):
                heapq.heappush(self.queue, (robot.clock, 1, other.index))


_EpisodeT = TypeVar("_EpisodeT", bound=EpisodeState)


def run_events(
    episode: _EpisodeT, planner: Any, oracle: bool = False, on_event: Callable[[_EpisodeT], None] | None = None
) -> tuple[list[list[float]], str]:
    """Run `episode`'s events until it is done or fails; a robot whose plan is used up decides with
    `planner.plan(episode.observe(robot))` (a `Planner` on an `Observation`, a `TeamPlanner` on a
    `TeamObservation`). Each robot's decision times (ms) and why the episode ended unexplored:
    "", IDLE (every robot waits), MOVE_LIMIT (a robot made `max_steps` moves) or "motion rule: ..."."""
    decision_ms: list[list[float]] = [[] for _ in episode.robots]
    loop = EventLoop(episode, oracle)
    if on_event is not None:
        on_event(episode)
    while (index := loop.next_decision(None if on_event is None else lambda _: on_event(episode))) is not None:
        observation = episode.observe(index)
        started = time.perf_counter()
        plan = list(planner.plan(observation))
        decision_ms[index].append((time.perf_counter() - started) * 1e3)
        loop.decide(index, plan)
    return decision_ms, loop.ending or ""
