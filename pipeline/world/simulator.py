"""Episodes under the benchmark protocol: sensing, the motion rule, the done rule, metrics.

The simulator is the referee: planners only propose waypoints, and every waypoint is
checked here (on the lattice, segment known-free in the belief before the move), so no
planner can claim a distance the protocol would not allow.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from pipeline.world.geometry import segment_is_known_free
from pipeline.world.maps import GroundTruthMap
from pipeline.world.planner import Observation, Planner, reset_planner
from pipeline.world.protocol import Protocol
from pipeline.world.reachability import LEFTOVER_M2, largest_unseen_region, reachable_free
from pipeline.world.sensor import FREE, Belief, Lidar

LATTICE_TOLERANCE_M = 1e-3
STOPPED = "no reachable target left"  # the failure of an episode whose planner said it was done
PLANNER_DECISION = "planner"  # a planner's `decision_kind` when its own rule decided (pipeline.planners.whole_building)


class MotionError(Exception):
    """A waypoint that breaks the motion rule; the planner is in error."""


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


class Episode:
    """One robot on one map: belief, position, distance, and the protocol's rules."""

    def __init__(self, ground_truth: GroundTruthMap, protocol: Protocol):
        self.map = ground_truth
        self.protocol = protocol
        self.belief = Belief(ground_truth.shape)
        self.lidar = Lidar(ground_truth.free, protocol.sensor_range_cells)
        self.cell = ground_truth.start_cell
        self.position = (0.0, 0.0)
        self.trajectory: list[tuple[float, float]] = [(0.0, 0.0)]
        self.distance = 0.0
        self.distances: list[float] = [0.0]  # per trajectory row
        self.explored_cells: list[int] = []  # belief free cells after sensing at each trajectory row
        self.completion_distance: float | None = None
        self.complete_after_waypoint: int | None = None
        self._pending_changes: list[np.ndarray] = []
        self._first_observation = True
        self._sense()

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
        episode.map, episode.protocol = world, protocol
        episode.belief = Belief(world.shape)
        episode.belief.grid[...] = belief
        episode.belief.free_count = int((belief == FREE).sum())
        episode.lidar = Lidar(world.free, protocol.sensor_range_cells)
        episode.cell, episode.position = (int(cell[0]), int(cell[1])), (float(position[0]), float(position[1]))
        episode.trajectory = [episode.position]
        episode.distance = 0.0
        episode.distances = [0.0]
        episode.explored_cells = [episode.belief.free_count]
        episode.completion_distance = episode.complete_after_waypoint = None
        if episode.unknown_free_cells <= protocol.done_unknown_cells:
            episode.completion_distance, episode.complete_after_waypoint = 0.0, 1
        episode._pending_changes = []
        episode._first_observation = False
        return episode

    @property
    def steps(self) -> int:
        return len(self.trajectory) - 1

    @property
    def unknown_free_cells(self) -> int:
        return self.map.free_cell_count - self.belief.free_count

    @property
    def complete(self) -> bool:
        return self.complete_after_waypoint is not None

    @property
    def explored_ratio(self) -> float:
        return self.belief.free_count / max(1, self.map.free_cell_count)

    def _sense(self) -> None:
        result = self.lidar.scan(self.cell)
        changed = self.belief.apply(result)
        if changed.size:
            self._pending_changes.append(changed)
        self.explored_cells.append(self.belief.free_count)
        if self.completion_distance is None and self.unknown_free_cells <= self.protocol.done_unknown_cells:
            self.completion_distance = self.distance
            self.complete_after_waypoint = len(self.trajectory)

    def observe(self) -> Observation:
        """The belief and the cells changed since the last observation."""
        if self._first_observation:
            changed = None
            self._first_observation = False
        elif self._pending_changes:
            changed = np.unique(np.concatenate(self._pending_changes))
        else:
            changed = np.zeros(0, dtype=np.int64)
        self._pending_changes = []
        return Observation(self.belief.grid, self.position, self.cell, changed, self.steps)

    def waypoint_cell(self, waypoint: Sequence[float]) -> tuple[tuple[int, int], tuple[float, float]]:
        """(the cell, the exact position in metres) of a waypoint: a lattice node inside the grid, or,
        under the door-aware graph (`Protocol.uses_door_graph`), any cell's centre (a door node, or a
        cell on the way to a frontier the lattice does not reach)."""
        x, y = float(waypoint[0]), float(waypoint[1])
        if not (np.isfinite(x) and np.isfinite(y)):
            raise MotionError(f"waypoint ({x}, {y}) is not finite")
        d = self.protocol.node_resolution
        i, j = round(x / d), round(y / d)
        size = self.protocol.cell_size
        if abs(i * d - x) <= LATTICE_TOLERANCE_M and abs(j * d - y) <= LATTICE_TOLERANCE_M:
            position = (i * d, j * d)
            col = self.map.start_cell[0] + int(round(i * d / size))
            row = self.map.start_cell[1] + int(round(j * d / size))
        else:
            ci, cj = round(x / size), round(y / size)
            if (
                not self.protocol.uses_door_graph
                or abs(ci * size - x) > LATTICE_TOLERANCE_M
                or abs(cj * size - y) > LATTICE_TOLERANCE_M
            ):
                where = "a cell centre" if self.protocol.uses_door_graph else f"on the {d} m node lattice"
                raise MotionError(f"waypoint ({x:.3f}, {y:.3f}) is not {where}")
            position = (ci * size, cj * size)
            col, row = self.map.start_cell[0] + ci, self.map.start_cell[1] + cj
        rows, cols = self.map.shape
        if not (0 <= col < cols and 0 <= row < rows):
            raise MotionError(f"waypoint ({x:.3f}, {y:.3f}) lies outside the map")
        return (col, row), position

    def move(self, waypoint: Sequence[float], oracle: bool = False) -> None:
        """Move to a waypoint (`waypoint_cell`) through known-free cells, then sense there.

        `oracle=True` is the ground-truth planner's rule (docs/protocol.md, "The reference"):
        the segment need only be free in the ground truth, observed or not.
        """
        cell, target = self.waypoint_cell(waypoint)
        free = self.map.free if oracle else self.belief.grid == FREE
        if not segment_is_known_free(free, self.cell, cell):
            what = "ground-truth free" if oracle else "known to be free"
            raise MotionError(
                f"segment ({self.position[0]:.3f}, {self.position[1]:.3f}) -> "
                f"({float(waypoint[0]):.3f}, {float(waypoint[1]):.3f}) crosses cells not {what}"
            )
        self.distance += float(np.hypot(target[0] - self.position[0], target[1] - self.position[1]))
        self.position = target
        self.cell = cell
        self.trajectory.append(target)
        self.distances.append(self.distance)
        self._sense()


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
    decision_ms: list[float] = []
    waypoint_ms: list[float] = [0.0]  # per trajectory row: the start needs no decision
    waypoint_trust: list[float | None] = [None]
    waypoint_fallback: list[bool | None] = [False]
    failure = ""
    violations = 0
    oracle = bool(getattr(planner, "ignores_motion_rule", False))
    if on_step is not None:
        on_step(episode)
    while not episode.complete and episode.steps < protocol.max_steps:
        observation = episode.observe()
        t0 = time.perf_counter()
        waypoints = planner.plan(observation)
        decision_ms.append((time.perf_counter() - t0) * 1e3)
        trust = getattr(planner, "prediction_trust", None)
        fallback = getattr(planner, "decision_kind", PLANNER_DECISION) != PLANNER_DECISION
        if not waypoints:
            failure = STOPPED
            break
        try:
            for k, waypoint in enumerate(waypoints):
                episode.move(waypoint, oracle=oracle)
                waypoint_ms.append(decision_ms[-1] if k == 0 else 0.0)
                waypoint_trust.append(trust)
                waypoint_fallback.append(fallback)
                if on_step is not None:
                    on_step(episode)
                if episode.complete or episode.steps >= protocol.max_steps:
                    break
        except MotionError as error:
            failure = f"motion rule: {error}"
            violations += 1
            break
    if not episode.complete and not failure:
        failure = f"step limit ({protocol.max_steps}) reached"
    result = _result(episode, getattr(planner, "name", type(planner).__name__), seed, decision_ms, failure, violations)
    result.waypoint_decision_ms = waypoint_ms[: len(result.trajectory)]
    result.waypoint_trust = waypoint_trust[: len(result.trajectory)]
    result.waypoint_fallback = waypoint_fallback[: len(result.trajectory)]
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
    episode = Episode(ground_truth, protocol)
    failure = ""
    violations = 0
    for point in points[1:]:
        if episode.complete:
            break
        try:
            episode.move(point, oracle=oracle)
        except MotionError as error:
            failure = f"motion rule: {error}"
            violations = 1
            break
    if not episode.complete and not failure:
        failure = "trajectory ended before completion"
    return _result(episode, planner_name, 0, [], failure, violations)


def _result(
    episode: Episode, planner: str, seed: int, decision_ms: list[float], failure: str, violations: int
) -> EpisodeResult:
    complete = episode.complete
    reachable = reachable_free(episode.map.free, episode.map.start_cell, episode.protocol.robot_radius_cells)
    seen = int((reachable & (episode.belief.grid == FREE)).sum())
    unseen = int(reachable.sum()) - seen
    return EpisodeResult(
        map_name=episode.map.name,
        planner=planner,
        trajectory=list(episode.trajectory),
        distance_m=episode.completion_distance if complete else episode.distance,
        steps=(episode.complete_after_waypoint - 1) if complete else episode.steps,
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
        reachable_share=seen / max(1, seen + unseen),
        early_stop=failure == STOPPED
        and largest_unseen_region(reachable, episode.belief.grid, episode.protocol.robot_radius_cells)
        * episode.map.cell_size**2
        >= LEFTOVER_M2,
    )
