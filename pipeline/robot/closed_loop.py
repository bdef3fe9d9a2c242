"""The robot path in closed loop, without ROS: the simulator plays the robot and its SLAM.

At every decision the simulated belief goes out as a SLAM map would: an OccupancyGrid of
`slam_resolution` cells (0.05 m) with occupancy probabilities rather than three values, cropped to
the known area (so it grows and its origin moves), serialized to CDR and read back as ROS 2 does
(rosbags' message types, which have rclpy's fields); the pose carries noise (`pose_noise_m`, any
heading). The session plans; the robot drives to the first waypoint along the belief's known-free
cells (the shortest 8-connected path), scans every `scan_every_m` metres on the way, and stops
within `stop_within_m` of the waypoint; one goal in `fail_every` fails (the robot stays and the
session is told). The done rule is the protocol's, on the simulated belief.
"""

from __future__ import annotations

import functools
import heapq
import math
from dataclasses import dataclass, field
from typing import Any, cast

import cv2
import numpy as np

from pipeline.robot.occupancy_grid import GridMessage
from pipeline.robot.session import ExplorationSession
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.reachability import LEFTOVER_M2, largest_unseen_region, reachable_free
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN, Belief, Lidar
from pipeline.world.simulator import Episode

DECISION_S = 0.5  # simulated seconds between decisions (2 Hz)


@dataclass(frozen=True)
class ClosedLoopConfig:
    slam_resolution: float = 0.05  # metres per cell of the OccupancyGrid the session reads
    pose_noise_m: float = 0.1  # standard deviation of the reported position, each axis
    stop_within_m: float = 0.3  # the robot stops this close to its waypoint, or closer
    fail_every: int = 20  # one goal in this many fails (0: none)
    scan_every_m: float = 1.0  # the lidar scans this often along a drive
    max_decisions: int = 2000
    cdr: bool = True  # round-trip each map through CDR (needs rosbags)


@dataclass
class ClosedLoopResult:
    complete: bool
    distance_m: float  # driven until the protocol's done rule held (all of it when it never did)
    decisions: int
    failed_goals: int
    maps_skipped: int
    decision_ms: list[float] = field(default_factory=list)
    # The whole building (as `EpisodeResult`'s): the share of the free area a robot of the protocol's
    # radius reaches from the start that the belief holds at the end (ground truth, scoring only),
    # whether the session said done with an unseen region of it of LEFTOVER_M2 or more, and its fallbacks.
    reachable_share: float = 1.0
    early_stop: bool = False
    fallbacks: int = 0
    done: bool = False  # the session said `plan.done`


class SimulatedRobot:
    """A robot at a continuous position on the ground truth, with the protocol's lidar and a belief."""

    def __init__(self, ground_truth: GroundTruthMap, protocol: Protocol):
        self.map, self.protocol = ground_truth, protocol
        self.belief = Belief(ground_truth.shape)
        self.lidar = Lidar(ground_truth.free, protocol.sensor_range_cells)
        self.xy = (0.0, 0.0)  # metres from the start cell's centre (the simulator's world frame)
        self.distance = 0.0
        self.completion_distance: float | None = None
        self.sense()

    @property
    def cell(self) -> tuple[int, int]:
        c = self.protocol.cell_size
        return (
            self.map.start_cell[0] + int(round(self.xy[0] / c)),
            self.map.start_cell[1] + int(round(self.xy[1] / c)),
        )

    def sense(self) -> None:
        self.belief.apply(self.lidar.scan(self.cell))
        if (
            self.completion_distance is None
            and self.map.free_cell_count - self.belief.free_count <= self.protocol.done_unknown_cells
        ):
            self.completion_distance = self.distance

    def drive(
        self, goal: tuple[float, float], stop_within_m: float, scan_every_m: float, rng: np.random.Generator
    ) -> bool:
        """Drive along known-free cells to within `stop_within_m` of `goal`; False when no known-free
        path leads there (the robot stays)."""
        c = self.protocol.cell_size
        goal_cell = (self.map.start_cell[0] + int(round(goal[0] / c)), self.map.start_cell[1] + int(round(goal[1] / c)))
        path = free_path(self.belief.grid == FREE, self.cell, goal_cell)
        if path is None:
            return False
        stop = rng.uniform(0.0, stop_within_m)
        since_scan = 0.0
        for (col0, row0), (col1, row1) in zip(path[:-1], path[1:]):
            step = math.hypot(col1 - col0, row1 - row0) * c
            nxt = ((col1 - self.map.start_cell[0]) * c, (row1 - self.map.start_cell[1]) * c)
            if math.dist(nxt, goal) < stop and len(path) > 2:
                break
            self.xy = nxt
            self.distance += step
            since_scan += step
            if since_scan >= scan_every_m:
                self.sense()
                since_scan = 0.0
        self.sense()
        return True


def free_path(free: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> list[tuple[int, int]] | None:
    """The shortest 8-connected path of known-free cells from `start` to `goal` (col, row), or None."""
    rows, cols = free.shape
    if not (0 <= goal[0] < cols and 0 <= goal[1] < rows) or not free[goal[1], goal[0]]:
        return None
    best = {start: 0.0}
    came: dict[tuple[int, int], tuple[int, int]] = {}
    queue = [(math.dist(start, goal), 0.0, start)]
    steps = [(dx, dy, math.hypot(dx, dy)) for dx in (-1, 0, 1) for dy in (-1, 0, 1) if dx or dy]
    while queue:
        _, cost, cell = heapq.heappop(queue)
        if cell == goal:
            path = [cell]
            while cell in came:
                cell = came[cell]
                path.append(cell)
            return path[::-1]
        if cost > best.get(cell, math.inf):
            continue
        for dx, dy, length in steps:
            nxt = (cell[0] + dx, cell[1] + dy)
            if not (0 <= nxt[0] < cols and 0 <= nxt[1] < rows) or not free[nxt[1], nxt[0]]:
                continue
            if dx and dy and not (free[cell[1], nxt[0]] and free[nxt[1], cell[0]]):
                continue  # no corner cutting
            total = cost + length
            if total < best.get(nxt, math.inf):
                best[nxt], came[nxt] = total, cell
                heapq.heappush(queue, (total + math.dist(nxt, goal), total, nxt))
    return None


def slam_map(robot: SimulatedRobot | Episode, resolution: float, rng: np.random.Generator) -> dict[str, Any]:
    """The robot's (or a simulator episode's) belief as a SLAM map would give it: the fields of an
    OccupancyGrid, cropped to the known area, with occupancy probabilities.

    The ground truth ends in a wall: a cell just outside it, beside a known-free cell on its edge,
    reads as occupied, as a lidar would see the edge of a plan whose free space runs to its image
    border (the simulator's belief has no cell beyond it, so no frontier there either)."""
    grid = edge_walls(robot.belief.grid)
    c = robot.protocol.cell_size
    fine = max(1, int(round(c / resolution)))
    rows, cols = np.nonzero(grid != UNKNOWN)
    r0, r1, c0, c1 = rows.min(), rows.max() + 1, cols.min(), cols.max() + 1
    known = grid[r0:r1, c0:c1]
    values = np.where(
        known == FREE,
        rng.integers(0, 15, known.shape),
        np.where(known == OCCUPIED, rng.integers(70, 101, known.shape), -1),
    ).astype(np.int8)
    values = np.repeat(np.repeat(values, fine, axis=0), fine, axis=1)
    start_col, start_row = robot.map.start_cell[0] + 1, robot.map.start_cell[1] + 1  # in the grid with its edge
    return {
        "data": values.reshape(-1),
        "width": values.shape[1],
        "height": values.shape[0],
        "resolution": c / fine,
        "x": (c0 - start_col - 0.5) * c,
        "y": (r0 - start_row - 0.5) * c,
    }


def edge_walls(grid: np.ndarray) -> np.ndarray:
    """`grid` with one cell more on each side: unknown, but occupied beside a known-free edge cell."""
    edged = np.pad(grid, 1, constant_values=UNKNOWN)
    beside = cv2.dilate((edged == FREE).astype(np.uint8), np.ones((3, 3), np.uint8)).astype(bool)
    ring = np.ones(edged.shape, dtype=bool)
    ring[1:-1, 1:-1] = False
    edged[ring & beside] = OCCUPIED
    return edged


def grid_message(fields: dict[str, Any]) -> GridMessage:
    """`slam_map`'s fields as a message with OccupancyGrid's fields, without ROS types."""
    return GridMessage(
        fields["data"], fields["width"], fields["height"], fields["resolution"], fields["x"], fields["y"]
    )


@functools.cache
def ros2_typestore() -> Any:
    """rosbags' ROS 2 Humble type store, built once: building it compiles its serializers."""
    from rosbags.typesys import Stores, get_typestore  # optional: the robot extra (pip install '.[robot]')

    return get_typestore(Stores.ROS2_HUMBLE)


def as_ros_message(fields: dict[str, Any], stamp_s: float, cdr: bool = True) -> Any:
    """A nav_msgs/OccupancyGrid of rosbags' ROS 2 types, through CDR and back when `cdr`."""
    store = ros2_typestore()
    t = store.types
    sec = int(stamp_s)
    time_ = t["builtin_interfaces/msg/Time"](sec=sec, nanosec=int((stamp_s - sec) * 1e9))
    pose = t["geometry_msgs/msg/Pose"](
        position=t["geometry_msgs/msg/Point"](x=float(fields["x"]), y=float(fields["y"]), z=0.0),
        orientation=t["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0),
    )
    info = t["nav_msgs/msg/MapMetaData"](
        map_load_time=time_,
        resolution=float(fields["resolution"]),
        width=int(fields["width"]),
        height=int(fields["height"]),
        origin=pose,
    )
    kind = "nav_msgs/msg/OccupancyGrid"
    msg = t[kind](
        header=t["std_msgs/msg/Header"](stamp=time_, frame_id="map"),
        info=info,
        data=np.asarray(fields["data"], dtype=np.int8),
    )
    return store.deserialize_cdr(store.serialize_cdr(msg, kind), kind) if cdr else msg


def run_closed_loop(
    ground_truth: GroundTruthMap,
    session: ExplorationSession,
    config: ClosedLoopConfig = ClosedLoopConfig(),
    seed: int = 0,
) -> ClosedLoopResult:
    """Explore `ground_truth` with `session` driving a simulated robot (see the module's docstring)."""
    rng = np.random.default_rng(seed)
    robot = SimulatedRobot(ground_truth, session.protocol)
    now = [0.0]
    session.clock = lambda: now[0]  # simulated time: a decision every DECISION_S seconds
    session.update_pose(0.0, 0.0, 0.0)  # the lattice is anchored at the start
    failed, decision_ms, done = 0, [], False
    for decision in range(config.max_decisions):
        now[0] = decision * DECISION_S
        session.update_map(as_ros_message(slam_map(robot, config.slam_resolution, rng), now[0], config.cdr))
        noise = rng.normal(0.0, config.pose_noise_m, 2)
        session.update_pose(robot.xy[0] + noise[0], robot.xy[1] + noise[1], rng.uniform(-math.pi, math.pi))
        plan = session.plan()
        decision_ms.append(plan.decision_ms)
        if plan.done:
            done = True
            break
        if not plan.waypoints:
            continue
        goal = plan.waypoints[0]
        if (
            config.fail_every
            and rng.integers(config.fail_every) == 0
            or not robot.drive(goal, config.stop_within_m, config.scan_every_m, rng)
        ):
            failed += 1
            session.goal_failed(*goal)
    complete = robot.completion_distance is not None
    reachable = reachable_free(ground_truth.free, ground_truth.start_cell, session.protocol.robot_radius_cells)
    seen = int((reachable & (robot.belief.grid == FREE)).sum())
    unseen = int(reachable.sum()) - seen
    c2 = ground_truth.cell_size**2
    return ClosedLoopResult(
        complete,
        cast(float, robot.completion_distance) if complete else robot.distance,
        decision + 1,
        failed,
        session.state.maps_skipped,
        decision_ms,
        reachable_share=seen / max(1, seen + unseen),
        early_stop=done
        and largest_unseen_region(reachable, robot.belief.grid, session.protocol.robot_radius_cells) * c2
        >= LEFTOVER_M2,
        fallbacks=session.state.fallbacks,
        done=done,
    )
