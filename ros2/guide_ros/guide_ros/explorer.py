"""The GUIDE explorer node: a live SLAM map and tf in, plans, graph markers and Nav2 goals out.

Every decision is the exploration session's (`pipeline.robot.ExplorationSession`, the code our
tests run in closed loop); this node only moves messages:

    subscribes   <map_topic>          nav_msgs/OccupancyGrid (transient local, as slam_toolbox publishes)
                 tf                   map_frame -> base_frame, looked up at every tick
    publishes    ~/plan               nav_msgs/Path: the decision's waypoints
                 ~/waypoint           geometry_msgs/PointStamped: the next waypoint
                 ~/graph              visualization_msgs/MarkerArray: lattice, predicted and frontier nodes, edges
                 ~/decision           std_msgs/String: the decision's record as JSON
    action       navigate_to_pose     nav2_msgs/NavigateToPose, when send_goals is true (or ~/explore says so)
    service      ~/explore            std_srvs/SetBool: start (true) or stop (false) sending goals

A goal Nav2 aborts or rejects goes back to the session (`goal_failed`), which stops choosing it.
"""

from __future__ import annotations

import json
from typing import Any

import rclpy
from action_msgs.msg import GoalStatus
from geometry_msgs.msg import Point, PointStamped, PoseStamped, Quaternion, Vector3
from nav2_msgs.action import NavigateToPose
from nav_msgs.msg import OccupancyGrid, Path
from rclpy.action import ActionClient
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.time import Time
from std_msgs.msg import ColorRGBA, String
from std_srvs.srv import SetBool
from tf2_ros import Buffer, TransformException, TransformListener
from visualization_msgs.msg import Marker, MarkerArray

from pipeline.planners.specs import build_planner, resolve_planner_specs
from pipeline.robot import ExplorationSession
from pipeline.robot.recording import graph_view
from pipeline.robot.ros_messages import yaw_of

PARAMETERS = {
    "planner": "guide",
    "planner_options": "",
    "protocol": "real_robot",
    "map_topic": "/map",
    "map_frame": "map",
    "base_frame": "base_link",
    "rate_hz": 1.0,
    "send_goals": False,
    "navigate_action": "navigate_to_pose",
    "goal_tolerance_m": 0.5,
    "replan_changed_cells": 50,
    "replan_after_s": 5.0,
    "seed": 0,
}
MARKER_STYLE = {  # namespace: (marker type, size in node spacings, RGBA)
    "lattice": (Marker.SPHERE_LIST, 0.25, (0.55, 0.55, 0.55, 0.8)),
    "predicted": (Marker.SPHERE_LIST, 0.35, (0.15, 0.45, 0.95, 0.9)),
    "frontier": (Marker.SPHERE_LIST, 0.45, (1.0, 0.55, 0.0, 1.0)),
    "edges": (Marker.LINE_LIST, 0.05, (0.4, 0.4, 0.4, 0.5)),
}


def planner_from(name: str, options: str) -> Any:
    """The planner a name and its `key=value,...` options make (the command line's spec language)."""
    spec = f"{name}_ros={name}:{options}" if options.strip() else name
    (resolved,) = resolve_planner_specs([spec])
    return build_planner(resolved)


class GuideExplorer(Node):
    """The exploration session as a ROS 2 node (see the module's docstring)."""

    def __init__(self) -> None:
        super().__init__("guide_explorer")
        for name, default in PARAMETERS.items():
            self.declare_parameter(name, default)
        p = {name: self.get_parameter(name).value for name in PARAMETERS}
        self.map_frame, self.base_frame = p["map_frame"], p["base_frame"]
        self.send_goals = bool(p["send_goals"])
        self.session = ExplorationSession(
            planner_from(p["planner"], p["planner_options"]), p["protocol"], seed=int(p["seed"]),
            goal_tolerance_m=float(p["goal_tolerance_m"]), replan_changed_cells=int(p["replan_changed_cells"]),
            replan_after_s=float(p["replan_after_s"]))
        self.get_logger().info(f"{p['planner']}: {self.session.planner.description}")
        latched = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)
        self.create_subscription(OccupancyGrid, p["map_topic"], self.on_map, latched)
        self.tf_buffer = Buffer()
        self.tf_listener = TransformListener(self.tf_buffer, self)
        self.plan_pub = self.create_publisher(Path, "~/plan", 10)
        self.waypoint_pub = self.create_publisher(PointStamped, "~/waypoint", 10)
        self.graph_pub = self.create_publisher(MarkerArray, "~/graph", 1)
        self.decision_pub = self.create_publisher(String, "~/decision", 10)
        self.navigator = ActionClient(self, NavigateToPose, p["navigate_action"])
        self.create_service(SetBool, "~/explore", self.on_explore)
        self.goal: tuple[float, float] | None = None  # the waypoint Nav2 is driving to
        self.goal_handle = None
        self.reached = False  # Nav2 reached the goal: decide afresh at the next tick
        self.done = False
        self.create_timer(1.0 / float(p["rate_hz"]), self.tick)

    # ------------------------------------------------------------------ input
    def on_map(self, msg: OccupancyGrid) -> None:
        if msg.header.frame_id and msg.header.frame_id.lstrip("/") != self.map_frame.lstrip("/"):
            self.get_logger().warn(f"map in frame {msg.header.frame_id!r}, expected {self.map_frame!r}: skipped",
                                   throttle_duration_sec=10.0)
            return
        self.session.update_map(msg)

    def robot_pose(self) -> tuple[float, float, float] | None:
        try:
            t = self.tf_buffer.lookup_transform(self.map_frame, self.base_frame, Time())
        except TransformException as error:
            self.get_logger().info(f"waiting for tf {self.map_frame} -> {self.base_frame}: {error}",
                                   throttle_duration_sec=10.0)
            return None
        return t.transform.translation.x, t.transform.translation.y, yaw_of(t.transform.rotation)

    def on_explore(self, request: SetBool.Request, response: SetBool.Response) -> SetBool.Response:
        self.send_goals = bool(request.data)
        if not self.send_goals:
            self.cancel_goal()
        response.success, response.message = True, "sending goals" if self.send_goals else "goals stopped"
        return response

    # ------------------------------------------------------------------ decisions
    def tick(self) -> None:
        pose = self.robot_pose()
        if pose is None or not self.session.update_pose(*pose):
            return
        plan = self.session.plan(force=self.reached)
        self.reached = False
        if not plan.replanned:
            return
        now = self.get_clock().now().to_msg()
        self.publish_plan(plan, now)
        if plan.done and not self.done:
            self.get_logger().info("exploration done: nothing reachable is left to explore")
            self.cancel_goal()
        self.done = plan.done
        if self.send_goals and plan.waypoints and plan.waypoints[0] != self.goal:
            self.send_goal(plan.waypoints[0])

    def publish_plan(self, plan: Any, stamp: Any) -> None:
        path = Path()
        path.header.stamp, path.header.frame_id = stamp, self.map_frame
        for x, y in plan.waypoints:
            pose = PoseStamped()
            pose.header = path.header
            pose.pose.position.x, pose.pose.position.y = float(x), float(y)
            pose.pose.orientation.w = 1.0
            path.poses.append(pose)
        self.plan_pub.publish(path)
        if plan.waypoints:
            point = PointStamped()
            point.header = path.header
            point.point.x, point.point.y = map(float, plan.waypoints[0])
            self.waypoint_pub.publish(point)
        canvas = self.session.canvas
        if canvas is not None:
            self.graph_pub.publish(self.markers(graph_view(self.session.planner, canvas.to_map), path.header))
        record = {"reason": plan.reason, "done": plan.done, "target": plan.target, "decision_ms": round(plan.decision_ms, 3),
                  "waypoints": plan.waypoints, "maps_used": self.session.state.maps_used,
                  "maps_skipped": self.session.state.maps_skipped, "resets": self.session.state.resets}
        self.decision_pub.publish(String(data=json.dumps(record)))

    def markers(self, view: Any, header: Any) -> MarkerArray:
        spacing = self.session.protocol.node_resolution
        array = MarkerArray()
        for namespace, points in (("lattice", view.known), ("predicted", view.predicted),
                                  ("frontier", view.frontier), ("edges", view.edges.reshape(-1, 2))):
            kind, size, (r, g, b, a) = MARKER_STYLE[namespace]
            marker = Marker(header=header, ns=namespace, id=0, type=kind, action=Marker.ADD)
            marker.pose.orientation = Quaternion(w=1.0)
            marker.scale = Vector3(x=size * spacing, y=size * spacing, z=size * spacing)
            marker.color = ColorRGBA(r=r, g=g, b=b, a=a)
            marker.points = [Point(x=float(x), y=float(y)) for x, y in points]
            array.markers.append(marker)
        return array

    # ------------------------------------------------------------------ Nav2
    def send_goal(self, waypoint: tuple[float, float]) -> None:
        if not self.navigator.server_is_ready():
            self.get_logger().warn("Nav2's navigate_to_pose is not up: no goal sent", throttle_duration_sec=10.0)
            return
        goal = NavigateToPose.Goal()
        goal.pose.header.frame_id = self.map_frame
        goal.pose.header.stamp = self.get_clock().now().to_msg()
        goal.pose.pose.position.x, goal.pose.pose.position.y = map(float, waypoint)
        goal.pose.pose.orientation.w = 1.0
        self.goal = tuple(waypoint)
        self.navigator.send_goal_async(goal).add_done_callback(lambda future: self.on_goal_response(future, waypoint))

    def on_goal_response(self, future: Any, waypoint: tuple[float, float]) -> None:
        handle = future.result()
        if not handle.accepted:
            self.goal_failed(waypoint, "rejected")
            return
        self.goal_handle = handle
        handle.get_result_async().add_done_callback(lambda result: self.on_goal_result(result, waypoint))

    def on_goal_result(self, future: Any, waypoint: tuple[float, float]) -> None:
        status = future.result().status
        if status == GoalStatus.STATUS_SUCCEEDED:
            self.reached = True
        elif status != GoalStatus.STATUS_CANCELED:
            self.goal_failed(waypoint, f"status {status}")
        if self.goal == tuple(waypoint):
            self.goal = None

    def goal_failed(self, waypoint: tuple[float, float], why: str) -> None:
        self.get_logger().warn(f"Nav2 could not reach ({waypoint[0]:.2f}, {waypoint[1]:.2f}): {why}")
        self.session.goal_failed(*waypoint)
        if self.goal == tuple(waypoint):
            self.goal = None

    def cancel_goal(self) -> None:
        if self.goal_handle is not None:
            self.goal_handle.cancel_goal_async()
            self.goal_handle = None
        self.goal = None


def main(args: list[str] | None = None) -> None:
    rclpy.init(args=args)
    node = GuideExplorer()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        if rclpy.ok():
            rclpy.shutdown()


if __name__ == "__main__":
    main()
