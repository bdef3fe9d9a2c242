"""The single robot's episodes under the benchmark protocol: `run_episode`, `replay` and the metrics.

A single robot is a team of one (`pipeline.world.episode`): `Episode` is that state seen as one
robot, and `run_episode` runs the team's event loop with a `Planner` deciding.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from types import SimpleNamespace
from typing import Any, Callable, Sequence, cast

import numpy as np

from pipeline.world.episode import (
    IDLE,
    LATTICE_TOLERANCE_M,
    MOTION_RULE,
    MOVE_LIMIT,
    EpisodeState,
    Robot,
    run_events,
    waypoint_cell,
)
from pipeline.world.episode import MotionError as MotionError  # the simulator's error, for its callers
from pipeline.world.maps import GroundTruthMap
from pipeline.world.planner import Observation, Planner, reset_planner
from pipeline.world.protocol import Protocol
from pipeline.world.reachability import LEFTOVER_M2, largest_unseen_region, reachable_free
from pipeline.world.sensor import FREE, Belief

STOPPED = "no reachable target left"  # the failure of an episode whose planner said it was done
PLANNER_DECISION = "planner"  # a planner's `decision_kind` when its own rule decided (pipeline.planners.whole_building)


@dataclass
class EpisodeResult:
    map_name: str
    planner: str
    trajectory: list[tuple[float, float]]
    distance_m: float
    steps: int
    complete: bool
    explored_ratio: float
    decision_ms: list[float] = field(default_factory=list)
    seed: int = 0
    failure: str = ""
    motion_violations: int = 0
    complete_after_waypoint: int | None = None  # 1-based row of the trajectory, start = 1
    # Per trajectory row (the start first): distance so far, belief free cells after sensing there,
    # and the decision time charged to the row (a plan's time to its first waypoint, 0 to the rest).
    distances: list[float] = field(default_factory=list)
    explored_cells: list[int] = field(default_factory=list)
    waypoint_decision_ms: list[float] = field(default_factory=list)
    waypoint_trust: list[float | None] = field(default_factory=list)  # the planner's prediction trust per row
    free_cell_count: int = 0  # ground-truth free cells: the explored share's denominator
    cell_size: float = 0.0  # metres: a cell's area is cell_size ** 2
    # The whole building (docs/protocol.md): the share of the free area a robot of the protocol's
    # radius reaches from the start that the belief holds at the end (ground truth, scoring only);
    # the decisions that were not the planner's own rule (its nearest-frontier fallback and the way
    # back to the lattice), in all and per trajectory row; and whether the planner stopped while an
    # unseen region of that area of at least LEFTOVER_M2 was left (an early stop).
    reachable_share: float = 1.0
    fallbacks: int = 0
    waypoint_fallback: list[bool | None] = field(default_factory=list)
    early_stop: bool = False
    error_traceback: str = ""  # where a benchmark's planner raised (pipeline/evaluation/episode_errors.py)

    def step_rows(self) -> list[dict]:
        """The per-step record (docs/protocol.md, "Per-step files"): one row per trajectory row up to
        completion; `decision_ms` is None where the run measured none (a replay)."""
        area = self.cell_size**2
        timed = len(self.waypoint_decision_ms) == len(self.trajectory)
        trusted = len(self.waypoint_trust) == len(self.trajectory)
        marked = len(self.waypoint_fallback) == len(self.trajectory)
        return [
            {
                "step": step,
                "distance_m": self.distances[step],
                "explored_m2": self.explored_cells[step] * area,
                "explored_share": self.explored_cells[step] / max(1, self.free_cell_count),
                "decision_ms": self.waypoint_decision_ms[step] if timed else None,
                "prediction_trust": self.waypoint_trust[step] if trusted else None,
                "fallback": self.waypoint_fallback[step] if marked else None,
            }
            for step in range(len(self.trajectory))
        ]

    def metrics_row(self) -> dict:
        """One row of docs/protocol.md's metrics.csv."""
        ms = np.asarray(self.decision_ms, dtype=np.float64)
        return {
            "map": self.map_name,
            "planner": self.planner,
            "distance_m": round(self.distance_m, 3),
            "steps": self.steps,
            "complete": bool(self.complete),
            "explored_ratio": round(self.explored_ratio, 5),
            "decision_ms_median": round(float(np.median(ms)), 3) if ms.size else float("nan"),
            "decision_ms_p95": round(float(np.percentile(ms, 95)), 3) if ms.size else float("nan"),
            "seed": self.seed,
            "reachable_share": round(self.reachable_share, 5),
            "fallbacks": self.fallbacks,
            "early_stop": bool(self.early_stop),
        }


def _own(name: str, doc: str) -> property:
    """The robot's own field `name` of a team of one, as the single robot's attribute."""
    return property(lambda s: getattr(s.robots[0], name), lambda s, v: setattr(s.robots[0], name, v), doc=doc)


class Episode(EpisodeState):
    """One robot on one map (a team of one): its belief, position and distance, under the protocol's
    rules; `move` is one whole event, departure and arrival."""

    def __init__(self, ground_truth: GroundTruthMap, protocol: Protocol):
        super().__init__(ground_truth, protocol)

    @classmethod
    def resume(
        cls,
        world: GroundTruthMap,
        protocol: Protocol,
        belief: np.ndarray,
        cell: tuple[int, int],
        position: tuple[float, float],
    ) -> "Episode":
        """An episode on `world` that starts from a given belief and pose at distance 0, without a
        first scan: a planner's rollout on a map it imagines (`sampled_lookahead`)."""
        if belief.shape != world.shape:
            raise ValueError(f"belief {belief.shape} and world {world.shape} differ in shape")
        episode = cls.__new__(cls)
        robot = Robot(0, (float(position[0]), float(position[1])), (int(cell[0]), int(cell[1])))
        episode._setup(world, protocol, [robot], None)
        episode.belief.grid[...] = belief
        episode.belief.free_count = int((belief == FREE).sum())
        robot.explored, robot.first = [episode.belief.free_count], False
        episode.advance(0, 0.0)  # no arrival: the done rule on the given belief
        return episode

    @property
    def belief(self) -> Belief:
        return self.beliefs[0]

    cell = _own("cell", "(col, row)")
    position = _own("position", "metres from the start")
    trajectory = _own("trajectory", "positions, the start first")
    distance = _own("travelled", "metres so far")
    distances = _own("distances", "the distance so far per trajectory row")
    explored_cells = _own("explored", "belief free cells after sensing at each trajectory row")
    steps = _own("moves", "moves so far")

    @property
    def complete_after_waypoint(self) -> int | None:
        return self.completed_after[0] if self.complete else None  # 1-based trajectory row, start = 1

    @property
    def completion_distance(self) -> float | None:
        return self.distances[self.completed_after[0] - 1] if self.complete else None

    def waypoint_cell(self, waypoint: Sequence[float]) -> tuple[tuple[int, int], tuple[float, float]]:
        """`waypoint_cell` on this episode's map and protocol."""
        return waypoint_cell(self.map, self.protocol, waypoint)

    def move(self, waypoint: Sequence[float], oracle: bool = False) -> None:
        """Move to a waypoint (`waypoint_cell`) through known-free cells, then sense there.

        `oracle=True` is the ground-truth planner's rule (docs/protocol.md, "The reference"):
        the segment need only be free in the ground truth, observed or not.
        """
        self.depart(0, waypoint, oracle)
        self.advance(0, self.robots[0].clock)


class _Decisions:
    """A planner as the event loop calls it, keeping per decision what `EpisodeResult` reports per
    row: how many waypoints, the planner's prediction trust, and whether its own rule decided."""

    def __init__(self, planner: Planner):
        self.made: list[tuple[int, Any, bool]]  # per decision: waypoints, trust, fallback
        self.planner, self.made = planner, []

    def plan(self, observation: Observation) -> list:
        waypoints = list(self.planner.plan(observation))
        kind = getattr(self.planner, "decision_kind", PLANNER_DECISION)
        self.made.append((len(waypoints), getattr(self.planner, "prediction_trust", None), kind != PLANNER_DECISION))
        return waypoints

    def rows(self, decision_ms: list[float], rows: int) -> tuple[list[float], list, list]:
        """Per trajectory row (the start first, needing no decision): the decision time charged to
        it (a plan's time to its first waypoint, 0 to the rest), the trust and the fallback mark."""
        ms, trust, fallback = [0.0], [None], [False]
        for (count, trusted, fell_back), spent in zip(self.made, decision_ms):
            ms += [spent] + [0.0] * (count - 1) if count else []
            trust += [trusted] * count
            fallback += [fell_back] * count
        return ms[:rows], trust[:rows], fallback[:rows]


def final_belief(ground_truth: GroundTruthMap, trajectory: Sequence[Sequence[float]], protocol: Protocol) -> np.ndarray:
    """The belief at the end of an episode, rebuilt by replaying its trajectory (first row the start)."""
    episode = Episode(ground_truth, protocol)
    for waypoint in trajectory[1:]:
        episode.move(waypoint)
    return episode.belief.grid


def run_episode(
    ground_truth: GroundTruthMap,
    planner: Planner,
    protocol: Protocol,
    seed: int = 0,
    on_step: Callable[[Episode], None] | None = None,
) -> EpisodeResult:
    """Run `planner` until the map is explored, it fails, or `protocol.max_steps` waypoints."""
    episode = Episode(ground_truth, protocol)
    reset_planner(planner, ground_truth, protocol, seed)
    decisions = _Decisions(planner)
    oracle = bool(getattr(planner, "ignores_motion_rule", False))
    shown = [0]  # trajectory rows shown to `on_step`: it sees the start and every move

    def on_event(_: EpisodeState) -> None:
        if len(episode.trajectory) > shown[0]:
            shown[0] = len(episode.trajectory)
            cast(Callable[[Episode], None], on_step)(episode)

    decision_ms, ending = run_events(episode, decisions, oracle, on_event if on_step is not None else None)
    failure = {IDLE: STOPPED, MOVE_LIMIT: f"step limit ({protocol.max_steps}) reached"}.get(ending, ending)
    name = getattr(planner, "name", type(planner).__name__)
    result = _result(episode, name, seed, decision_ms[0], failure, int(failure.startswith(MOTION_RULE)))
    result.waypoint_decision_ms, result.waypoint_trust, result.waypoint_fallback = decisions.rows(
        decision_ms[0], len(result.trajectory)
    )
    result.fallbacks = int(getattr(planner, "fallbacks", 0))
    return result


def replay(
    ground_truth: GroundTruthMap,
    waypoints: Sequence[Sequence[float]],
    protocol: Protocol,
    planner_name: str = "replay",
    oracle: bool = False,
) -> EpisodeResult:
    """Replay a trajectory file's waypoints (first row the start) through a fresh simulator.

    The distance reported is the distance at completion; waypoints after completion are
    not counted. A motion-rule violation stops the replay. `oracle=True` replays under the
    ground-truth planner's rule (segments free in the ground truth).
    """
    points = [tuple(map(float, p)) for p in waypoints]
    if not points:
        raise ValueError("a trajectory needs at least its start row")
    if abs(points[0][0]) > LATTICE_TOLERANCE_M or abs(points[0][1]) > LATTICE_TOLERANCE_M:
        raise ValueError(f"a trajectory's first row must be the start (0, 0), got {points[0]}")
    episode = Episode(ground_truth, replace(protocol, max_steps=len(points)))  # every row, however many
    script = iter([points[1:]])  # one plan: the file's moves
    _, ending = run_events(episode, SimpleNamespace(plan=lambda _: next(script, [])), oracle)
    motion = ending.startswith(MOTION_RULE)
    return _result(
        episode, planner_name, 0, [], ending if motion else "trajectory ended before completion", int(motion)
    )


def _result(
    episode: Episode, planner: str, seed: int, decision_ms: list[float], failure: str, violations: int
) -> EpisodeResult:
    complete = episode.complete
    reachable = reachable_free(episode.map.free, episode.map.start_cell, episode.protocol.robot_radius_cells)
    seen = int((reachable & (episode.belief.grid == FREE)).sum())
    return EpisodeResult(
        map_name=episode.map.name,
        planner=planner,
        trajectory=list(episode.trajectory),
        distance_m=cast(float, episode.completion_distance) if complete else episode.distance,
        steps=(cast(int, episode.complete_after_waypoint) - 1) if complete else episode.steps,
        complete=complete,
        explored_ratio=episode.explored_ratio,
        decision_ms=decision_ms,
        seed=seed,
        failure="" if complete else failure,
        motion_violations=violations,
        complete_after_waypoint=episode.complete_after_waypoint,
        distances=list(episode.distances),
        explored_cells=list(episode.explored_cells),
        free_cell_count=episode.map.free_cell_count,
        cell_size=episode.map.cell_size,
        reachable_share=seen / max(1, int(reachable.sum())),
        early_stop=failure == STOPPED
        and largest_unseen_region(reachable, episode.belief.grid, episode.protocol.robot_radius_cells)
        * episode.map.cell_size**2
        >= LEFTOVER_M2,
    )
