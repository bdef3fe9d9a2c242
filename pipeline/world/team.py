"""Team episodes: N robots on one map under the protocol, in time order (`pipeline.world.episode`,
whose state and event loop a single robot shares), on DARE's lattice whatever the scale.

The episode fails when every robot waits, when a move breaks the motion rule, or when a robot
has made `max_steps` moves.

The team trajectory file (`write_team_csv`) has one row per arrival, the starts first;
`replay_team` checks it: every row's segment from its robot's previous row must be known-free
in the belief built from all earlier rows. That is the rule itself with full communication and
a looser one under a range (the union belief knows more than any robot): merges are listed in
the file beside it (`<map>.team.merges.csv`) so a replay can rebuild each robot's belief.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence, cast

import numpy as np

from pipeline.world.episode import IDLE, MOTION_RULE, MOVE_LIMIT, EpisodeState, run_events, waypoint_cell
from pipeline.world.maps import GroundTruthMap, MapFrame
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.team_files import MAX_ROBOTS as MAX_ROBOTS  # the largest team, for the commands


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
    planner.reset(cast(MapFrame, world), protocol, seed, robots)  # an oracle's reset takes the map itself


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


class TeamEpisode(EpisodeState):
    """N robots on one map: beliefs, positions and the protocol's rules, in time order; moves on the
    lattice (`team_protocol`)."""

    names_robots = True
    _length = staticmethod(math.hypot)

    def __init__(
        self,
        ground_truth: GroundTruthMap,
        protocol: Protocol,
        robots: int,
        starts: Sequence[Sequence[float]] | None = None,
        comm_range_m: float | None = None,
    ):
        super().__init__(ground_truth, team_protocol(protocol), robots, starts, comm_range_m)

    def observe(self, robot: int) -> TeamObservation:  # type: ignore[override]  # a team's view adds its teammates'
        """Robot `robot`'s view before it decides; its pending changes are handed over."""
        own = super().observe(robot)
        positions, targets = list(self.heard_positions[robot]), list(self.heard_targets[robot])
        positions[robot], targets[robot] = own.position, self.robots[robot].target
        return TeamObservation(robot, own, tuple(positions), tuple(targets), tuple(self.connected[robot]), self.time)

    def result(
        self, planner: str, decision_ms: list[list[float]], failure: str, violations: int, seed: int
    ) -> TeamEpisodeResult:
        end = cast(float, self.completion_time) if self.complete else self.time
        return TeamEpisodeResult(
            map_name=self.map.name,
            planner=planner,
            robots=len(self.robots),
            rows=[row for row in self.rows if row[0] <= end],
            complete=self.complete,
            makespan_m=float(end),
            robot_distance_m=[r.travelled for r in self.robots],
            explored_ratio=self.explored_ratio,
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


def lattice_cell(world: GroundTruthMap | MapFrame, protocol: Protocol, point: Sequence[float]) -> tuple[int, int]:
    """The cell of a lattice node given in metres from the start; MotionError when it is off the
    lattice, not finite or outside the map."""
    return waypoint_cell(world, team_protocol(protocol) if protocol.uses_door_graph else protocol, point)[0]


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
    episode = TeamEpisode(ground_truth, protocol, robots, starts, comm_range_m)
    reset_team_planner(planner, ground_truth, episode.protocol, seed, robots)
    oracle = bool(getattr(planner, "ignores_motion_rule", False))  # the ground-truth reference's rule only
    decision_ms, ending = run_events(episode, planner, oracle, on_event)
    failure = {
        IDLE: "no reachable target left for any robot",
        MOVE_LIMIT: f"step limit ({protocol.max_steps} moves of a robot) reached",
    }.get(ending, ending)
    name = getattr(planner, "name", "") or type(planner).__name__
    return episode.result(name, decision_ms, failure, int(failure.startswith(MOTION_RULE)), seed)
