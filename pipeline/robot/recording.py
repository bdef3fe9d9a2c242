"""MCAP recordings of exploration for Foxglove and `ros2 bag play`: maps, poses, plans, graphs.

One file per run, written with the `mcap` library: each topic's messages are rosbags' ROS 2
types serialized to CDR, under a `ros2msg` schema (the message definition), which is what a
ROS 2 bag in MCAP holds. The topics:

    /map               nav_msgs/OccupancyGrid        the map the decision saw
    /tf                tf2_msgs/TFMessage            map -> base_link, the robot's pose
    /guide/plan        nav_msgs/Path                 the waypoints of the decision
    /guide/waypoint    geometry_msgs/PointStamped    the next waypoint
    /guide/graph       visualization_msgs/MarkerArray  lattice, predicted and frontier nodes, edges
    /guide/decision    std_msgs/String               the decision's record as JSON

`graph_view` reads a planner's lattice graph (and its global graph, for the predicting planners)
into map-frame points; `EpisodeRecording` records a simulated episode step by step.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Callable, cast

import numpy as np

from pipeline.lattice.graph import NODE_FREE
from pipeline.planners.wrapper import PlannerWrapper, innermost
from pipeline.prediction.global_graph import CENTROID, PREDICTED
from pipeline.robot import ros_messages as ros
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN

MAP_TOPIC, TF_TOPIC = "/map", "/tf"
PLAN_TOPIC, WAYPOINT_TOPIC, GRAPH_TOPIC, DECISION_TOPIC = (
    "/guide/plan",
    "/guide/waypoint",
    "/guide/graph",
    "/guide/decision",
)
TYPES = {
    MAP_TOPIC: "nav_msgs/msg/OccupancyGrid",
    TF_TOPIC: "tf2_msgs/msg/TFMessage",
    PLAN_TOPIC: "nav_msgs/msg/Path",
    WAYPOINT_TOPIC: "geometry_msgs/msg/PointStamped",
    GRAPH_TOPIC: "visualization_msgs/msg/MarkerArray",
    DECISION_TOPIC: "std_msgs/msg/String",
}


class McapRecording:
    """An MCAP file being written: `write(topic, msg, seconds)` with the topic's type from TYPES
    (or `typename`); `close()` (or the `with` block's end) writes its index."""

    def __init__(self, path: str | Path) -> None:
        from mcap.writer import Writer  # optional: the robot extra

        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")
        self._writer = Writer(self._file)
        self._writer.start(profile="ros2", library="guide")
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self.counts: dict[str, int] = {}

    def write(self, topic: str, msg: Any, seconds: float, typename: str | None = None) -> None:
        typename = typename or TYPES[topic]
        store = ros.typestore()
        if topic not in self._channels:
            if typename not in self._schemas:
                text, _ = store.generate_msgdef(typename, ros_version=2)
                self._schemas[typename] = self._writer.register_schema(typename, "ros2msg", text.encode())
            self._channels[topic] = self._writer.register_channel(topic, "cdr", self._schemas[typename])
        nanoseconds = int(round(seconds * 1e9))
        data = bytes(store.serialize_cdr(msg, typename))
        self.counts[topic] = self.counts.get(topic, 0) + 1
        self._writer.add_message(
            self._channels[topic],
            log_time=nanoseconds,
            data=data,
            publish_time=nanoseconds,
            sequence=self.counts[topic],
        )

    def close(self) -> None:
        if not self._file.closed:
            self._writer.finish()
            self._file.close()

    def __enter__(self) -> "McapRecording":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


def graph_view(planner: Any, to_map: Callable[[tuple[float, float]], tuple[float, float]]) -> ros.GraphView:
    """The planner's graph in the map frame (`to_map` takes a planner position, metres from its
    start): an empty view for a planner without a lattice graph."""
    base = innermost(planner)
    graph = getattr(base, "graph", None)
    if graph is None or not hasattr(graph, "node_state"):
        return ros.GraphView()

    def points(xy: np.ndarray) -> np.ndarray:
        return np.array([to_map((float(x), float(y))) for x, y in np.asarray(xy).reshape(-1, 2)]).reshape(-1, 2)

    known = np.flatnonzero(graph.node_state == NODE_FREE)
    frontier = known[np.asarray(graph.utility)[known] > 0]
    edges = np.asarray(graph.edges).reshape(-1, 2)
    global_graph = getattr(base, "global_graph", None)
    predicted = np.zeros((0, 2))
    if global_graph is not None and len(getattr(global_graph, "types", ())):
        predicted = global_graph.positions[np.isin(global_graph.types, (PREDICTED, CENTROID))]
    return ros.GraphView(
        known=points(graph.node_world[known]),
        predicted=points(predicted),
        frontier=points(graph.node_world[frontier]),
        edges=points(graph.node_world[edges.reshape(-1)]).reshape(-1, 2, 2),
    )


def belief_grid_message(belief: np.ndarray, cell_size: float, start_cell: tuple[int, int], seconds: float) -> Any:
    """A simulator belief as an OccupancyGrid in the planner's frame (the start at the origin, rows
    along +y): free 0, occupied 100, unknown -1."""
    values = np.where(belief == FREE, 0, np.where(belief == OCCUPIED, 100, -1)).astype(np.int8)
    values[belief == UNKNOWN] = -1
    rows, cols = belief.shape
    origin = (-(start_cell[0] + 0.5) * cell_size, -(start_cell[1] + 0.5) * cell_size)
    return ros.occupancy_grid(values, cols, rows, cell_size, origin, seconds)


def record_decision(
    recording: McapRecording,
    seconds: float,
    waypoints: list[tuple[float, float]],
    view: ros.GraphView,
    node_resolution: float,
    record: dict[str, Any],
) -> None:
    """One decision: its plan, next waypoint, graph markers and JSON record."""
    recording.write(PLAN_TOPIC, ros.path_message(waypoints, seconds), seconds)
    if waypoints:
        recording.write(WAYPOINT_TOPIC, ros.point_stamped(*waypoints[0], seconds), seconds)
    recording.write(GRAPH_TOPIC, ros.marker_array(view, seconds, node_resolution), seconds)
    recording.write(DECISION_TOPIC, ros.string_message(record), seconds)


class PlanCapture(PlannerWrapper):
    """A planner as it is, keeping the waypoints of its last decision (`last_waypoints`) for a
    recording of the episode."""

    def __init__(self, inner: Any) -> None:
        super().__init__(inner)
        self.last_waypoints: list[tuple[float, float]] = []
        self.decisions = 0

    def plan(self, observation: Any) -> list[tuple[float, float]]:
        waypoints = self.inner.plan(observation)
        self.last_waypoints = cast(list[tuple[float, float]], [tuple(map(float, w)) for w in waypoints])
        self.decisions += 1
        return waypoints


class EpisodeRecording:
    """A simulated episode into an MCAP file, one sample per waypoint reached (`on_step`): the belief
    as /map, the robot as /tf, and at each new decision its plan and graph. Time runs at
    `speed_mps` along the trajectory, so scrubbing the file follows the robot."""

    def __init__(self, path: str | Path, planner: Any, speed_mps: float = 1.0) -> None:
        self.recording = McapRecording(path)
        self.planner = PlanCapture(planner)
        self.speed_mps = speed_mps
        self._recorded_decisions = 0
        self._heading = 0.0

    def on_step(self, episode: Any) -> None:
        seconds = episode.distance / self.speed_mps
        protocol = episode.protocol
        trajectory = episode.trajectory
        if len(trajectory) >= 2 and trajectory[-1] != trajectory[-2]:
            (x0, y0), (x1, y1) = trajectory[-2], trajectory[-1]
            self._heading = math.atan2(y1 - y0, x1 - x0)
        x, y = episode.position
        self.recording.write(TF_TOPIC, ros.tf_message(x, y, self._heading, seconds), seconds)  # the pose before its map
        self.recording.write(
            MAP_TOPIC,
            belief_grid_message(episode.belief.grid, protocol.cell_size, episode.map.start_cell, seconds),
            seconds,
        )
        if self.planner.decisions > self._recorded_decisions:
            self._recorded_decisions = self.planner.decisions
            record = {
                "decision": self.planner.decisions,
                "distance_m": round(episode.distance, 3),
                "explored_share": round(episode.explored_ratio, 5),
                "waypoints": self.planner.last_waypoints,
                **_decision_fields(self.planner),
            }
            record_decision(
                self.recording,
                seconds,
                self.planner.last_waypoints,
                graph_view(self.planner, lambda xy: xy),
                protocol.node_resolution,
                record,
            )

    def close(self) -> Path:
        self.recording.close()
        return self.recording.path


def _decision_fields(planner: Any) -> dict[str, Any]:
    """What a planner says of its last decision (`last_decision`), as plain values."""
    decision = getattr(planner, "last_decision", None) or {}
    fields = {key: value for key, value in decision.items() if isinstance(value, (int, float, str, bool, type(None)))}
    trust = getattr(planner, "trust_state", None)
    if trust is not None:
        fields["prediction_trust"] = trust.as_dict()
    return fields
