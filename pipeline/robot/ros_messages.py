"""ROS 2 messages for what a session sees and decides, built with rosbags' ROS 2 types (real CDR).

The session reads any object with a message's fields; these builders make the messages a robot
would publish or a bag would hold: the map (`nav_msgs/OccupancyGrid`), the robot's pose as tf
(`tf2_msgs/TFMessage`, map -> base_link), a plan (`nav_msgs/Path`), the next waypoint
(`geometry_msgs/PointStamped`), the graph (`visualization_msgs/MarkerArray`: lattice nodes,
predicted nodes, frontier nodes, edges) and a decision's record as JSON (`std_msgs/String`).
`TfTree` composes a bag's transforms into the robot's pose in the map frame.

rosbags is an optional dependency (`pip install '.[robot]'`); the ROS 2 node uses rclpy's own
message classes, which have the same fields.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import lru_cache
from typing import Any, Iterable

import numpy as np

MAP_FRAME = "map"
BASE_FRAME = "base_link"
MARKER_NAMESPACES = ("lattice", "predicted", "frontier", "edges")


@lru_cache(maxsize=1)
def typestore() -> Any:
    """rosbags' ROS 2 (Humble) type store; ImportError saying what to install when rosbags is missing."""
    try:
        from rosbags.typesys import Stores, get_typestore
    except ImportError as error:  # pragma: no cover - the robot extra is in the test extras
        raise ImportError("ROS 2 bags and messages need rosbags and mcap: pip install '.[robot]'") from error
    return get_typestore(Stores.ROS2_HUMBLE)


def _types() -> dict[str, Any]:
    return typestore().types


def stamp(seconds: float) -> Any:
    """A builtin_interfaces/Time of `seconds`."""
    sec = int(math.floor(seconds))
    return _types()["builtin_interfaces/msg/Time"](sec=sec, nanosec=int(round((seconds - sec) * 1e9)) % 1_000_000_000)


def stamp_seconds(time_msg: Any) -> float:
    return float(time_msg.sec) + float(time_msg.nanosec) * 1e-9


def header(seconds: float, frame_id: str = MAP_FRAME) -> Any:
    return _types()["std_msgs/msg/Header"](stamp=stamp(seconds), frame_id=frame_id)


def _point(x: float, y: float, z: float = 0.0) -> Any:
    return _types()["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=float(z))


def _quaternion(yaw: float) -> Any:
    return _types()["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2.0), w=math.cos(yaw / 2.0))


def _pose(x: float, y: float, yaw: float = 0.0) -> Any:
    return _types()["geometry_msgs/msg/Pose"](position=_point(x, y), orientation=_quaternion(yaw))


def occupancy_grid(
    data: np.ndarray,
    width: int,
    height: int,
    resolution: float,
    origin: tuple[float, float],
    seconds: float,
    frame_id: str = MAP_FRAME,
) -> Any:
    """A nav_msgs/OccupancyGrid: `data` row-major from the origin cell's corner, -1 unknown, 0-100."""
    t = _types()
    info = t["nav_msgs/msg/MapMetaData"](
        map_load_time=stamp(seconds),
        resolution=float(resolution),
        width=int(width),
        height=int(height),
        origin=_pose(*origin),
    )
    return t["nav_msgs/msg/OccupancyGrid"](
        header=header(seconds, frame_id), info=info, data=np.asarray(data, dtype=np.int8).reshape(-1)
    )


def tf_message(x: float, y: float, yaw: float, seconds: float, parent: str = MAP_FRAME, child: str = BASE_FRAME) -> Any:
    """A tf2_msgs/TFMessage holding one transform: `child` at (x, y, yaw) in `parent`."""
    t = _types()
    transform = t["geometry_msgs/msg/Transform"](
        translation=t["geometry_msgs/msg/Vector3"](x=float(x), y=float(y), z=0.0), rotation=_quaternion(yaw)
    )
    stamped = t["geometry_msgs/msg/TransformStamped"](
        header=header(seconds, parent), child_frame_id=child, transform=transform
    )
    return t["tf2_msgs/msg/TFMessage"](transforms=[stamped])


def path_message(points: Iterable[tuple[float, float]], seconds: float, frame_id: str = MAP_FRAME) -> Any:
    """A nav_msgs/Path through `points` (map frame, metres)."""
    t = _types()
    poses = [t["geometry_msgs/msg/PoseStamped"](header=header(seconds, frame_id), pose=_pose(x, y)) for x, y in points]
    return t["nav_msgs/msg/Path"](header=header(seconds, frame_id), poses=poses)


def point_stamped(x: float, y: float, seconds: float, frame_id: str = MAP_FRAME) -> Any:
    return _types()["geometry_msgs/msg/PointStamped"](header=header(seconds, frame_id), point=_point(x, y))


def string_message(payload: dict[str, Any]) -> Any:
    """A std_msgs/String holding `payload` as JSON (a decision's record)."""
    return _types()["std_msgs/msg/String"](data=json.dumps(payload, default=_plain))


def _plain(value: Any) -> Any:
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, np.ndarray):
        return value.tolist()
    return str(value)


@dataclass(frozen=True)
class GraphView:
    """A planner's graph in the map frame, for markers: lattice nodes it knows free, the nodes it
    predicts in unknown space, the known nodes with frontier utility, and known-free edges."""

    known: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    predicted: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    frontier: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))
    edges: np.ndarray = field(default_factory=lambda: np.zeros((0, 2, 2)))  # (edge, end, xy)


def marker_array(view: GraphView, seconds: float, node_size_m: float, frame_id: str = MAP_FRAME) -> Any:
    """A visualization_msgs/MarkerArray of `view`: lattice nodes grey, predicted nodes blue,
    frontier nodes orange (sphere lists), edges as thin grey lines. Each namespace replaces its
    previous marker (id 0), so a viewer shows the latest graph only."""
    t = _types()
    colours = {
        "lattice": (0.55, 0.55, 0.55, 0.8),
        "predicted": (0.15, 0.45, 0.95, 0.9),
        "frontier": (1.0, 0.55, 0.0, 1.0),
        "edges": (0.4, 0.4, 0.4, 0.5),
    }
    marker_type = t["visualization_msgs/msg/Marker"]
    markers = []
    for namespace, points, kind, size in (
        ("lattice", view.known, marker_type.SPHERE_LIST, node_size_m * 0.25),
        ("predicted", view.predicted, marker_type.SPHERE_LIST, node_size_m * 0.35),
        ("frontier", view.frontier, marker_type.SPHERE_LIST, node_size_m * 0.45),
        ("edges", view.edges.reshape(-1, 2), marker_type.LINE_LIST, node_size_m * 0.05),
    ):
        r, g, b, a = colours[namespace]
        markers.append(
            marker_type(
                header=header(seconds, frame_id),
                ns=namespace,
                id=0,
                type=kind,
                action=marker_type.ADD,
                pose=_pose(0.0, 0.0),
                scale=t["geometry_msgs/msg/Vector3"](x=size, y=size, z=size),
                color=t["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=a),
                lifetime=t["builtin_interfaces/msg/Duration"](sec=0, nanosec=0),
                frame_locked=False,
                points=[_point(x, y) for x, y in np.asarray(points, dtype=np.float64).reshape(-1, 2)],
                colors=[],
                texture_resource="",
                texture=t["sensor_msgs/msg/CompressedImage"](
                    header=header(seconds, frame_id), format="", data=np.zeros(0, dtype=np.uint8)
                ),
                uv_coordinates=[],
                text="",
                mesh_resource="",
                mesh_file=t["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, dtype=np.uint8)),
                mesh_use_embedded_materials=False,
            )
        )
    return t["visualization_msgs/msg/MarkerArray"](markers=markers)


def yaw_of(quaternion: Any) -> float:
    """The heading (about z) of a quaternion with x, y, z, w."""
    x, y, z, w = (float(quaternion.x), float(quaternion.y), float(quaternion.z), float(quaternion.w))
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


class TfTree:
    """The latest transform of each frame from its parent, as a bag's /tf and /tf_static give
    them; `pose` composes the chain from the map frame down to the robot's base (2D: x, y, yaw)."""

    def __init__(self) -> None:
        self.parent: dict[str, tuple[str, float, float, float]] = {}  # child -> (parent, x, y, yaw)

    def update(self, tf_msg: Any) -> None:
        for transform in tf_msg.transforms:
            translation, rotation = transform.transform.translation, transform.transform.rotation
            values = (float(translation.x), float(translation.y), yaw_of(rotation))
            if all(math.isfinite(v) for v in values):
                self.parent[_frame(transform.child_frame_id)] = (_frame(transform.header.frame_id), *values)

    def pose(self, map_frame: str = MAP_FRAME, base_frame: str = BASE_FRAME) -> tuple[float, float, float] | None:
        """The base frame's (x, y, yaw) in the map frame; None until the chain joins them."""
        x, y, yaw = 0.0, 0.0, 0.0
        frame, seen = _frame(base_frame), set()
        target = _frame(map_frame)
        while frame != target:
            if frame in seen or frame not in self.parent:
                return None
            seen.add(frame)
            parent, px, py, pyaw = self.parent[frame]
            # this frame's pose in its parent, composed with what we have so far (expressed in this frame)
            x, y = px + math.cos(pyaw) * x - math.sin(pyaw) * y, py + math.sin(pyaw) * x + math.cos(pyaw) * y
            yaw += pyaw
            frame = parent
        return x, y, math.atan2(math.sin(yaw), math.cos(yaw))


def _frame(name: str) -> str:
    return str(name).lstrip("/")
