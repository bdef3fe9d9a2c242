"""A team file replayed under the rule: each robot's segment known-free in the team's belief from
all earlier rows (or free in the ground truth for the team oracle), and the team figures it
gives.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from pipeline.world.episode import MotionError, waypoint_cell
from pipeline.world.geometry import segment_is_known_free
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, Belief, Lidar
from pipeline.world.team import team_protocol
from pipeline.world.team_files import team_size


@dataclass
class TeamReplay:
    """A team file replayed: whether it keeps the rule, and the team figures it gives."""

    complete: bool
    robots: int
    makespan_s: float
    robot_distance_m: list[float]
    explored_ratio: float
    failure: str = ""
    motion_violations: int = 0

    @property
    def total_distance_m(self) -> float:
        return float(sum(self.robot_distance_m))


def replay_team(
    ground_truth: GroundTruthMap,
    rows: Sequence[tuple[float, int, float, float]],
    protocol: Protocol,
    oracle: bool = False,
) -> TeamReplay:
    """Replay a team file's rows: each row's segment from its robot's previous row must be
    known-free in the belief built from all earlier rows (the team's belief with full
    communication); with `oracle`, free in the ground truth (the team `optimal` reference's
    rule). Rows after done are not counted."""
    protocol = team_protocol(protocol)
    robots = team_size(rows)
    if robots == 0:
        raise ValueError("a team file starts with one row per robot at time 0 (robots 0, 1, ...)")
    belief = Belief(ground_truth.shape)
    lidar = Lidar(ground_truth.free, protocol.sensor_range_cells)
    cells, where, travelled = [], [], [0.0] * robots
    for t, robot, x, y in rows[:robots]:
        cell, point = waypoint_cell(ground_truth, protocol, (x, y))
        cells.append(cell)
        where.append(point)
        belief.apply(lidar.scan(cell))

    def done() -> bool:
        return ground_truth.free_cell_count - belief.free_count <= protocol.done_unknown_cells

    end, failure, violations = 0.0, "", 0
    if not done():
        for t, robot, x, y in rows[robots:]:
            if robot >= robots:
                failure = f"robot {robot} has no start row"
                break
            try:
                cell, point = waypoint_cell(ground_truth, protocol, (x, y))
            except MotionError as error:
                failure, violations = f"motion rule: robot {robot}: {error}", 1
                break
            if not segment_is_known_free(ground_truth.free if oracle else belief.grid == FREE, cells[robot], cell):
                failure, violations = (
                    (
                        f"motion rule: robot {robot}: segment ({where[robot][0]:g}, {where[robot][1]:g}) -> "
                        f"({x:g}, {y:g}) at {t:g} s crosses cells not known to be free"
                    ),
                    1,
                )
                break
            travelled[robot] += math.hypot(point[0] - where[robot][0], point[1] - where[robot][1])
            cells[robot], where[robot], end = cell, point, t
            belief.apply(lidar.scan(cell))
            if done():
                break
    complete = done()
    if not complete and not failure:
        failure = "the file ends before the map is explored"
    return TeamReplay(
        complete,
        robots,
        end,
        travelled,
        belief.free_count / max(1, ground_truth.free_cell_count),
        "" if complete else failure,
        violations,
    )
