"""Team episodes: N robots on one map under the protocol, in time order.

Every robot has the protocol's lidar and motion rule and the same speed, so time is counted in
metres of travel. Events run in time order: the robot that arrives next senses, the beliefs
update, and that robot decides when its plan is used up; a move must be known-free in the
belief its robot holds when it departs. With full communication (`comm_range_m` None) the team
holds one belief. With a range, each robot holds its own; robots within `comm_range_m` of each
other, or linked through a chain of robots that are, merge theirs at every event (positions
of robots on the way are interpolated along their segment). The done rule applies to the union
of all beliefs.

A robot whose planner finds nothing to do waits and asks again after the next arrival (a
teammate may open new frontier); the episode fails when every robot waits, when a move breaks
the motion rule, or when a robot has made `max_steps` moves.

The team trajectory file (`write_team_csv`) has one row per arrival, the starts first;
`replay_team` checks it: every row's segment from its robot's previous row must be known-free
in the belief built from all earlier rows. That is the rule itself with full communication and
a looser one under a range (the union belief knows more than any robot): merges are listed in
the file beside it (`<map>.team.merges.csv`) so a replay can rebuild each robot's belief.
"""

from __future__ import annotations

import heapq
import math
import time
from abc import ABC, abstractmethod
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np

from pipeline.world.geometry import segment_is_known_free
from pipeline.world.maps import GroundTruthMap, MapFrame
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN, Belief, Lidar
from pipeline.world.simulator import LATTICE_TOLERANCE_M, MotionError
from pipeline.world.team_files import MAX_ROBOTS


@dataclass(frozen=True)
class TeamObservation:
    """What a team planner sees before robot `robot` decides.

    `observation` is that robot's own: its belief (the team's with full communication), pose,
    the cells changed in its belief since its previous decision and its own move count.
    `positions` and `targets` are every robot's as this robot knows them: current for the
    robots it is connected to (itself included), as of their last contact for the others.
    A target is the last waypoint of a robot's current plan (None before its first plan or
    while it waits). `time_m` is the team's clock in metres of travel.
    """

    robot: int
    observation: Observation
    positions: tuple[Waypoint, ...]
    targets: tuple[Waypoint | None, ...]
    connected: tuple[bool, ...]
    time_m: float

    @property
    def robots(self) -> int:
        return len(self.positions)


class TeamPlanner(ABC):
    """Decides for one robot of a team at a time; `reset` once per episode.

    A planner that does not see the ground truth is reset with the map's frame; an oracle
    (`uses_ground_truth = True`) with the map itself.
    """

    name: str = ""
    description: str = ""
    uses_ground_truth: bool = False
    ignores_motion_rule: bool = False  # only the ground-truth team reference may set this

    @abstractmethod
    def reset(self, frame: MapFrame, protocol: Protocol, seed: int, robots: int) -> None:
        """Prepare for a new episode of `robots` robots on a map of this frame."""

    @abstractmethod
    def plan(self, observation: TeamObservation) -> list[Waypoint]:
        """Robot `observation.robot`'s next lattice waypoints in world metres; [] when it has nothing to do."""

    def check_protocol(self, protocol: Protocol) -> None:
        """Warn when a trained model was trained at other protocol values; nothing to say by default."""


def reset_team_planner(
    planner: TeamPlanner, ground_truth: GroundTruthMap, protocol: Protocol, seed: int, robots: int
) -> None:
    """Reset `planner` for an episode: an oracle gets the map, any other its frame only."""
    world = ground_truth if getattr(planner, "uses_ground_truth", False) else ground_truth.frame
    planner.reset(world, protocol, seed, robots)


@dataclass
class TeamEpisodeResult:
    """A team episode: its arrivals, per-robot and team figures (distances and times in metres)."""

    map_name: str
    planner: str
    robots: int
    rows: list[tuple[float, int, float, float]]  # (time_m, robot, x, y): the starts, then every arrival
    complete: bool
    makespan_m: float  # the team's time at done (or at the end of a failed episode)
    robot_distance_m: list[float]  # each robot's finished moves up to that time (as a replay of the file counts them)
    explored_ratio: float
    decision_ms: list[list[float]]  # per robot
    coverage: list[tuple[float, float]]  # (time_m, explored share of the union belief) after every event
    merges: list[tuple[float, tuple[int, ...]]] = field(default_factory=list)  # (time_m, robots) that merged
    comm_range_m: float | None = None
    failure: str = ""
    motion_violations: int = 0
    seed: int = 0
    free_cell_count: int = 0
    cell_size: float = 0.0

    @property
    def total_distance_m(self) -> float:
        return float(sum(self.robot_distance_m))

    def time_to_share(self, share: float) -> float:
        """The team's time (metres) when the union belief first held `share` of the free cells; nan if never."""
        for t, explored in self.coverage:
            if explored >= share:
                return t
        return float("nan")

    def metrics_row(self) -> dict:
        """One row of the team metrics file (docs/teams.md)."""
        ms = np.asarray([m for robot in self.decision_ms for m in robot], dtype=np.float64)
        return {
            "map": self.map_name,
            "planner": self.planner,
            "robots": self.robots,
            "comm_range_m": "" if self.comm_range_m is None else self.comm_range_m,
            "makespan_m": round(self.makespan_m, 3),
            "total_distance_m": round(self.total_distance_m, 3),
            "max_robot_distance_m": round(max(self.robot_distance_m), 3),
            "time_to_90_m": round(self.time_to_share(0.9), 3),
            "complete": bool(self.complete),
            "explored_ratio": round(self.explored_ratio, 5),
            "decision_ms_median": round(float(np.median(ms)), 3) if ms.size else float("nan"),
            "merges": len(self.merges),
            "seed": self.seed,
        }


class _Robot:
    """One robot's state in the event loop."""

    def __init__(self, index: int, position: Waypoint, cell: tuple[int, int]):
        self.index = index
        self.position, self.cell = position, cell
        self.clock = 0.0  # time of its next event: arrival at `heading`, or its next decision
        self.departed_at = 0.0
        self.origin = position  # where the move under way started
        self.heading: tuple[Waypoint, tuple[int, int]] | None = None  # (waypoint, cell) of the move under way
        self.plan: list[Waypoint] = []
        self.target: Waypoint | None = None
        self.waiting = False  # planned nothing: asks again after the next arrival
        self.stopped = False  # made max_steps moves: stays where it is
        self.moves = 0
        self.travelled = 0.0  # finished moves
        self.pending: list[np.ndarray] = []  # cells changed in its belief since its last decision
        self.first = True

    def location(self, t: float) -> Waypoint:
        """Where it is at time t (on its segment while it moves)."""
        if self.heading is None:
            return self.position
        (x1, y1), (x0, y0) = self.heading[0], self.origin
        length = math.hypot(x1 - x0, y1 - y0)
        share = 1.0 if length == 0 else min(1.0, max(0.0, (t - self.departed_at) / length))
        return (x0 + share * (x1 - x0), y0 + share * (y1 - y0))


class TeamEpisode:
    """N robots on one map: beliefs, positions and the protocol's rules, in time order."""

    def __init__(
        self,
        ground_truth: GroundTruthMap,
        protocol: Protocol,
        robots: int,
        starts: Sequence[Sequence[float]] | None = None,
        comm_range_m: float | None = None,
    ):
        if not 1 <= int(robots) <= MAX_ROBOTS:
            raise ValueError(f"robots must be 1-{MAX_ROBOTS}, got {robots}")
        if comm_range_m is not None and not (math.isfinite(comm_range_m) and comm_range_m > 0):
            raise ValueError(f"comm_range_m must be a positive number of metres, got {comm_range_m}")
        self.map, self.protocol, self.comm_range_m = ground_truth, protocol, comm_range_m
        self.lidar = Lidar(ground_truth.free, protocol.sensor_range_cells)
        points = [(0.0, 0.0)] * robots if starts is None else [tuple(map(float, s)) for s in starts]
        if len(points) != robots:
            raise ValueError(f"{len(points)} starts given for {robots} robots")
        self.robots = []
        for k, point in enumerate(points):
            cell = lattice_cell(ground_truth, protocol, point)
            if not ground_truth.free[cell[1], cell[0]]:
                raise ValueError(f"start of robot {k} ({point[0]:g}, {point[1]:g}) is not a free cell")
            self.robots.append(_Robot(k, snap(point, protocol), cell))
        shared = comm_range_m is None
        one = Belief(ground_truth.shape)
        self.beliefs = [one] * robots if shared else [Belief(ground_truth.shape) for _ in range(robots)]
        self.union = one if shared else Belief(ground_truth.shape)
        # What each robot last heard of each teammate: position and target (its own: always current).
        self.heard_positions = [[r.position for r in self.robots] for _ in self.robots]
        self.heard_targets: list[list[Waypoint | None]] = [[None] * robots for _ in self.robots]
        self.connected = [[True] * robots for _ in self.robots]
        self.time = 0.0
        self.rows: list[tuple[float, int, float, float]] = [(0.0, r.index, *r.position) for r in self.robots]
        self.coverage: list[tuple[float, float]] = []
        self.merges: list[tuple[float, tuple[int, ...]]] = []
        self.completion_time: float | None = None
        for robot in self.robots:
            self._sense(robot)
        self._communicate()
        self._record()

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

    def _sense(self, robot: _Robot) -> None:
        result = self.lidar.scan(robot.cell)
        changed = self.beliefs[robot.index].apply(result)
        if self.shared:
            if changed.size:
                for other in self.robots:
                    other.pending.append(changed)
        else:
            if changed.size:
                robot.pending.append(changed)
            self.union.apply(result)

    def groups(self) -> list[list[int]]:
        """The robots linked by communication now: all of them with full communication; else the
        connected groups of the within-range graph (positions interpolated on the way)."""
        n = len(self.robots)
        if self.shared:
            return [list(range(n))]
        where = np.array([r.location(self.time) for r in self.robots])
        near = np.hypot(*(where[:, None, :] - where[None, :, :]).transpose(2, 0, 1)) <= self.comm_range_m
        seen, groups = set(), []
        for k in range(n):
            if k in seen:
                continue
            stack, group = [k], []
            seen.add(k)
            while stack:
                a = stack.pop()
                group.append(a)
                for b in np.nonzero(near[a])[0]:
                    if int(b) not in seen:
                        seen.add(int(b))
                        stack.append(int(b))
            groups.append(sorted(group))
        return groups

    def _communicate(self) -> None:
        """Merge the beliefs of every linked group and pass on positions and targets."""
        groups = self.groups()
        for group in groups:
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
        self.coverage.append((self.time, self.union.free_count / max(1, self.map.free_cell_count)))

    # -- one robot ----------------------------------------------------------------------------
    def observe(self, robot: int) -> TeamObservation:
        """Robot `robot`'s view before it decides; its pending changes are handed over."""
        r = self.robots[robot]
        if r.first:
            changed, r.first = None, False
        elif r.pending:
            changed = np.unique(np.concatenate(r.pending))
        else:
            changed = np.zeros(0, dtype=np.int64)
        r.pending = []
        own = Observation(self.beliefs[robot].grid, r.position, r.cell, changed, r.moves)
        positions = list(self.heard_positions[robot])
        targets = list(self.heard_targets[robot])
        positions[robot], targets[robot] = r.position, r.target
        return TeamObservation(robot, own, tuple(positions), tuple(targets), tuple(self.connected[robot]), self.time)

    def depart(self, robot: int, waypoint: Sequence[float], oracle: bool = False) -> None:
        """Start robot `robot`'s move to a lattice waypoint: known-free in its belief now (with
        `oracle`, the ground-truth reference's rule: free in the ground truth)."""
        r = self.robots[robot]
        cell = lattice_cell(self.map, self.protocol, waypoint)
        free = self.map.free if oracle else self.beliefs[robot].grid == FREE
        if not segment_is_known_free(free, r.cell, cell):
            what = "ground-truth free" if oracle else "known to be free"
            raise MotionError(
                f"robot {robot}: segment ({r.position[0]:.3f}, {r.position[1]:.3f}) -> "
                f"({float(waypoint[0]):.3f}, {float(waypoint[1]):.3f}) crosses cells not {what}"
            )
        target = snap(waypoint, self.protocol)
        r.origin, r.departed_at = r.position, self.time
        r.heading = (target, cell)
        r.clock = self.time + math.hypot(target[0] - r.position[0], target[1] - r.position[1])

    def arrive(self, robot: int) -> None:
        """Robot `robot` reaches the end of its move: it senses there and the beliefs update."""
        r = self.robots[robot]
        (target, cell), r.heading = r.heading, None
        r.travelled += math.hypot(target[0] - r.origin[0], target[1] - r.origin[1])
        r.position, r.cell = target, cell
        r.moves += 1
        self.rows.append((self.time, robot, *target))
        self._sense(r)

    def result(
        self, planner: str, decision_ms: list[list[float]], failure: str, violations: int, seed: int
    ) -> TeamEpisodeResult:
        end = self.completion_time if self.complete else self.time
        rows = [row for row in self.rows if row[0] <= end]
        return TeamEpisodeResult(
            map_name=self.map.name,
            planner=planner,
            robots=len(self.robots),
            rows=rows,
            complete=self.complete,
            makespan_m=float(end),
            robot_distance_m=[r.travelled for r in self.robots],
            explored_ratio=self.union.free_count / max(1, self.map.free_cell_count),
            decision_ms=decision_ms,
            coverage=[c for c in self.coverage if c[0] <= end],
            merges=[m for m in self.merges if m[0] <= end],
            comm_range_m=self.comm_range_m,
            failure="" if self.complete else failure,
            motion_violations=violations,
            seed=seed,
            free_cell_count=self.map.free_cell_count,
            cell_size=self.map.cell_size,
        )


def snap(point: Sequence[float], protocol: Protocol) -> Waypoint:
    """A waypoint put exactly on its lattice node (metres)."""
    d = protocol.node_resolution
    return (round(float(point[0]) / d) * d, round(float(point[1]) / d) * d)


def lattice_cell(world: GroundTruthMap | MapFrame, protocol: Protocol, point: Sequence[float]) -> tuple[int, int]:
    """The cell of a lattice node given in metres from the start; MotionError when it is off the
    lattice, not finite or outside the map."""
    x, y = float(point[0]), float(point[1])
    if not (math.isfinite(x) and math.isfinite(y)):
        raise MotionError(f"waypoint ({x}, {y}) is not finite")
    d = protocol.node_resolution
    i, j = round(x / d), round(y / d)
    if abs(i * d - x) > LATTICE_TOLERANCE_M or abs(j * d - y) > LATTICE_TOLERANCE_M:
        raise MotionError(f"waypoint ({x:.3f}, {y:.3f}) is not on the {d} m node lattice")
    start = world.start_cell
    col = start[0] + int(round(i * d / protocol.cell_size))
    row = start[1] + int(round(j * d / protocol.cell_size))
    rows, cols = world.shape if isinstance(world, MapFrame) else world.free.shape
    if not (0 <= col < cols and 0 <= row < rows):
        raise MotionError(f"waypoint ({x:.3f}, {y:.3f}) lies outside the map")
    return col, row


def team_protocol(protocol: Protocol) -> Protocol:
    """The protocol a team runs under: DARE's lattice of straight edges, whatever the scale. A team's
    moves are checked on the lattice (`lattice_cell`); door nodes are the single robot's."""
    return replace(protocol, door_graph=False)


def run_team_episode(
    ground_truth: GroundTruthMap,
    planner: TeamPlanner,
    protocol: Protocol,
    robots: int,
    starts: Sequence[Sequence[float]] | None = None,
    comm_range_m: float | None = None,
    seed: int = 0,
    on_event: Callable[[TeamEpisode], None] | None = None,
) -> TeamEpisodeResult:
    """Run a team of `robots` with `planner` until the union belief is explored, a move breaks the
    motion rule, every robot waits with nothing to do, or a robot has made `max_steps` moves."""
    protocol = team_protocol(protocol)
    episode = TeamEpisode(ground_truth, protocol, robots, starts, comm_range_m)
    reset_team_planner(planner, ground_truth, protocol, seed, robots)
    decision_ms: list[list[float]] = [[] for _ in range(robots)]
    failure, violations = "", 0
    oracle = bool(getattr(planner, "ignores_motion_rule", False))  # the ground-truth reference's rule only
    # Events: (time, waiting, robot). At one time, arrivals and decisions come before the
    # retries of waiting robots, and lower robot numbers first.
    queue = [(0.0, 0, r.index) for r in episode.robots]
    heapq.heapify(queue)
    if on_event is not None:
        on_event(episode)
    while queue and not episode.complete:
        t, _, index = heapq.heappop(queue)
        robot = episode.robots[index]
        episode.time = t
        if robot.heading is not None:
            episode.arrive(index)
        episode._communicate()
        episode._record()
        if on_event is not None:
            on_event(episode)
        if episode.complete:
            break
        if robot.moves >= protocol.max_steps:
            robot.stopped, robot.target = True, None  # it stays where it is for the rest of the episode
            continue
        if not robot.plan:
            observation = episode.observe(index)
            started = time.perf_counter()
            robot.plan = list(planner.plan(observation))
            decision_ms[index].append((time.perf_counter() - started) * 1e3)
            robot.target = tuple(map(float, robot.plan[-1])) if robot.plan else None
            episode.heard_targets[index][index] = robot.target
        if not robot.plan:
            robot.waiting = True
            moving = [r.clock for r in episode.robots if r.heading is not None]
            if not moving:
                if not queue:  # nobody moves and nobody is left to decide
                    failure = "no reachable target left for any robot"
                    break
                continue  # another robot decides at this time: if it moves, this one asks again
            heapq.heappush(queue, (min(moving), 1, index))
            continue
        robot.waiting = False
        try:
            episode.depart(index, robot.plan.pop(0), oracle)
        except MotionError as error:
            failure, violations = f"motion rule: {error}", 1
            break
        heapq.heappush(queue, (robot.clock, 0, index))
        for other in episode.robots:  # a robot waiting with nobody moving asks again now that one is
            if other.waiting and not other.stopped and not any(e[2] == other.index for e in queue):
                heapq.heappush(queue, (robot.clock, 1, other.index))
    if not episode.complete and not failure:
        failure = (
            f"step limit ({protocol.max_steps} moves of a robot) reached"
            if any(r.stopped for r in episode.robots)
            else "no reachable target left for any robot"
        )
    name = getattr(planner, "name", "") or type(planner).__name__
    return episode.result(name, decision_ms, failure, violations, seed)
