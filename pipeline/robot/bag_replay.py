"""A recorded ROS 2 bag through an exploration session: a plan at every map the robot's SLAM made.

`replay_bag` reads a bag (rosbags: a rosbag2 folder in sqlite3 or MCAP, or a lone .mcap file)
holding the map topic and tf, in time order. Each transform updates a tf tree; each map goes to
the session with the robot's pose at that moment (map -> base_link, composed through odom or any
chain), and the session decides afresh. The output MCAP (`recording.py`'s topics) holds the input
map, the pose, and each decision's plan, next waypoint, graph markers and JSON record, so that the
bag and GUIDE's plans can be scrubbed together in Foxglove or played with `ros2 bag play`.
"""

from __future__ import annotations

import statistics
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

from tqdm import tqdm

from pipeline.robot import ros_messages as ros
from pipeline.robot.recording import MAP_TOPIC, TF_TOPIC, McapRecording, graph_view, record_decision
from pipeline.robot.session import ExplorationSession

TF_TOPICS = ("/tf", "/tf_static")


@dataclass
class BagReplay:
    """What a replay did: maps read, plans made, maps before any pose (no plan possible), maps
    the session skipped (and why, last), and each decision's time."""

    out: Path
    maps: int = 0
    plans: int = 0
    waiting: int = 0
    skipped: int = 0
    last_skip: str = ""
    done: bool = False
    decision_ms: list[float] = field(default_factory=list)

    def summary(self) -> str:
        timing = f"decision {statistics.median(self.decision_ms):.1f} ms median" if self.decision_ms else "no decision"
        parts = [f"{self.maps} maps", f"{self.plans} plans"]
        if self.waiting:
            parts.append(f"{self.waiting} before the first pose")
        if self.skipped:
            parts.append(f"{self.skipped} skipped ({self.last_skip})")
        return ", ".join(parts) + f"; {timing}" + ("; exploration done" if self.done else "") + f" -> {self.out}"


def bag_topics(bag: Path) -> dict[str, tuple[str, int]]:
    """Each topic of the bag: (message type, message count)."""
    from rosbags.highlevel import AnyReader  # optional: the robot extra

    topics: dict[str, tuple[str, int]] = {}
    with AnyReader([Path(bag)], default_typestore=ros.typestore()) as reader:
        for connection in reader.connections:
            kind, count = topics.get(connection.topic, (connection.msgtype, 0))
            topics[connection.topic] = (kind, count + connection.msgcount)
    return topics


def check_map_topic(bag: Path, map_topic: str) -> int:
    """How many maps the bag's `map_topic` holds; ValueError naming the bag's topics when it has
    none, or when the topic holds something other than maps."""
    topics = bag_topics(bag)
    if map_topic not in topics:
        raise ValueError(
            f"{bag}: no {map_topic} topic; it has: {', '.join(sorted(topics)) or 'none'} "
            "(choose the map with --map-topic)"
        )
    kind, count = topics[map_topic]
    if kind != "nav_msgs/msg/OccupancyGrid":
        raise ValueError(f"{bag}: {map_topic} holds {kind}, not nav_msgs/msg/OccupancyGrid")
    return count


def bag_messages(bag: Path, map_topic: str) -> Iterator[tuple[str, float, Any]]:
    """(kind 'map' or 'tf', seconds, message) of the bag's map topic and tf topics, in time order."""
    from rosbags.highlevel import AnyReader

    with AnyReader([Path(bag)], default_typestore=ros.typestore()) as reader:
        wanted = [c for c in reader.connections if c.topic == map_topic or c.topic in TF_TOPICS]
        for connection, timestamp, raw in reader.messages(connections=wanted):
            kind = "map" if connection.topic == map_topic else "tf"
            yield kind, timestamp * 1e-9, reader.deserialize(raw, connection.msgtype)


def replay_bag(
    bag: Path,
    out: Path,
    session: ExplorationSession,
    map_topic: str = "/map",
    base_frame: str = ros.BASE_FRAME,
    progress: bool = False,
) -> BagReplay:
    """Run `session` along the bag (a fresh decision at every map) and record it all in `out`."""
    result = BagReplay(Path(out))
    tree = ros.TfTree()
    total = check_map_topic(bag, map_topic)
    messages = bag_messages(bag, map_topic)
    with (
        McapRecording(out) as recording,
        tqdm(total=total, desc=f"{Path(bag).name}: maps", disable=not progress, leave=False) as bar,
    ):
        for kind, seconds, msg in messages:
            if kind == "tf":
                tree.update(msg)
                continue
            result.maps += 1
            bar.update(1)
            recording.write(MAP_TOPIC, msg, seconds)
            map_frame = str(getattr(msg.header, "frame_id", "") or ros.MAP_FRAME)
            session.update_map(msg)
            pose = tree.pose(map_frame, base_frame)
            if pose is None:
                result.waiting += 1
                continue
            session.update_pose(*pose)
            recording.write(TF_TOPIC, ros.tf_message(*pose, seconds, parent=map_frame, child=base_frame), seconds)
            plan = session.plan(force=True)
            if not plan.replanned:  # waiting for a usable map or pose: what the session says is in its state
                continue
            result.plans += 1
            result.done = plan.done
            result.decision_ms.append(plan.decision_ms)
            canvas = session.canvas
            view = graph_view(session.planner, canvas.to_map) if canvas is not None else ros.GraphView()
            record = {
                "map": result.maps,
                "stamp_s": seconds,
                "pose": list(pose),
                "reason": plan.reason,
                "done": plan.done,
                "target": plan.target,
                "decision_ms": round(plan.decision_ms, 3),
                "waypoints": plan.waypoints,
                "maps_skipped": session.state.maps_skipped,
                "resets": session.state.resets,
            }
            if session.state.prediction_trust is not None:
                record["prediction_trust"] = session.state.prediction_trust
            record_decision(recording, seconds, plan.waypoints, view, session.protocol.node_resolution, record)
    result.skipped, result.last_skip = session.state.maps_skipped, session.state.last_skip
    return result
