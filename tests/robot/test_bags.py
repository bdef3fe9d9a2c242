"""Recorded bags: a ROS 2 bag (sqlite3 or MCAP) with /map and /tf through a session, a plan at every
map, and MCAP recordings that the mcap library's ROS 2 decoder reads back."""

from __future__ import annotations

import json
import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

pytest.importorskip("rosbags")
pytest.importorskip("mcap_ros2")

from mcap.reader import make_reader  # noqa: E402
from mcap_ros2.decoder import DecoderFactory  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer  # noqa: E402

from pipeline.cli import app  # noqa: E402
from pipeline.robot import ExplorationSession  # noqa: E402
from pipeline.robot import ros_messages as ros  # noqa: E402
from pipeline.robot.bag_replay import replay_bag  # noqa: E402
from pipeline.robot.closed_loop import SimulatedRobot, slam_map  # noqa: E402
from pipeline.world.protocol import Protocol  # noqa: E402

runner = CliRunner()


def decoded(path: Path) -> dict[str, list]:
    """Every message of an MCAP file by topic, decoded with the mcap library's ROS 2 decoder."""
    topics: dict[str, list] = {}
    with open(path, "rb") as file:
        for _, channel, _, message in make_reader(file, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            topics.setdefault(channel.topic, []).append(message)
    return topics


def write_slam_bag(path: Path, maze, storage: StoragePlugin, maps: int = 6) -> list[tuple[float, float]]:
    """A robot's rosbag2 as SLAM would record it: a growing map at 0.05 m cells (cropped to the
    known area, so its origin moves), map -> odom -> base_link tf with an odom drift, the robot
    driving between nodes. Returns the robot's map-frame positions at each map."""
    protocol = Protocol()
    robot = SimulatedRobot(maze, protocol)
    rng = np.random.default_rng(5)
    store = ros.typestore()
    positions = []
    with Writer(path, version=9, storage_plugin=storage) as writer:
        topics = {
            name: writer.add_connection(name, kind, typestore=store)
            for name, kind in (("/map", "nav_msgs/msg/OccupancyGrid"), ("/tf", "tf2_msgs/msg/TFMessage"))
        }
        goals = [(4.0, 0.0), (8.0, 0.0), (8.0, 4.0), (4.0, 4.0), (0.0, 4.0), (0.0, 0.0)]
        for index in range(maps):
            seconds = 1.0 + index
            drift = (0.3 * index, -0.2 * index, 0.05 * index)  # map -> odom moves as SLAM corrects odometry
            x, y = robot.xy
            ox, oy = x - drift[0], y - drift[1]  # the robot in odom: undo the drift's translation, then rotation
            c, s = math.cos(-drift[2]), math.sin(-drift[2])
            odom_xy = (c * ox - s * oy, s * ox + c * oy)
            for parent, child, (tx, ty, yaw) in (("map", "odom", drift), ("odom", "base_link", (*odom_xy, -drift[2]))):
                writer.write(
                    topics["/tf"],
                    int((seconds - 0.01) * 1e9),
                    store.serialize_cdr(ros.tf_message(tx, ty, yaw, seconds, parent, child), "tf2_msgs/msg/TFMessage"),
                )
            fields = slam_map(robot, 0.05, rng)
            grid = ros.occupancy_grid(
                fields["data"],
                fields["width"],
                fields["height"],
                fields["resolution"],
                (fields["x"], fields["y"]),
                seconds,
            )
            writer.write(topics["/map"], int(seconds * 1e9), store.serialize_cdr(grid, "nav_msgs/msg/OccupancyGrid"))
            positions.append(robot.xy)
            robot.drive(goals[index % len(goals)], 0.3, 2.0, rng)
    return positions


@pytest.mark.parametrize("storage", [StoragePlugin.SQLITE3, StoragePlugin.MCAP])
def test_every_map_of_a_slam_bag_gets_a_plan_from_the_pose_tf_gives(storage, small_maze, tmp_path):
    positions = write_slam_bag(tmp_path / "bag", small_maze, storage)
    session = ExplorationSession("greedy_utility", "maze")
    result = replay_bag(tmp_path / "bag", tmp_path / "out.mcap", session)
    assert (result.maps, result.plans, result.waiting, result.skipped) == (6, 6, 0, 0), result
    topics = decoded(tmp_path / "out.mcap")
    assert {topic: len(messages) for topic, messages in topics.items()} == {
        "/map": 6,
        "/tf": 6,
        "/guide/plan": 6,
        "/guide/waypoint": 6,
        "/guide/graph": 6,
        "/guide/decision": 6,
    }
    for tf, (x, y) in zip(topics["/tf"], positions):  # tf composed through the drifting odom frame
        pose = tf.transforms[0].transform.translation
        assert (pose.x, pose.y) == (pytest.approx(x, abs=1e-6), pytest.approx(y, abs=1e-6))
    for plan, record in zip(topics["/guide/plan"], topics["/guide/decision"]):
        assert plan.header.frame_id == "map" and len(plan.poses) >= 1
        waypoints = json.loads(record.data)["waypoints"]
        got = [(p.pose.position.x, p.pose.position.y) for p in plan.poses]
        assert np.allclose(got, waypoints)
    namespaces = [marker.ns for marker in topics["/guide/graph"][-1].markers]
    assert namespaces == list(ros.MARKER_NAMESPACES)
    assert len(topics["/guide/graph"][-1].markers[0].points) > 5  # the lattice nodes known free


def test_guide_explore_records_a_bag_that_guide_bag_plans_at_every_map(small_maze_path, tmp_path):
    recorded = tmp_path / "explore" / "run.mcap"
    result = runner.invoke(
        app,
        [
            "explore",
            "--map",
            str(small_maze_path),
            "--planner",
            "greedy_utility",
            "--out",
            str(tmp_path / "explore"),
            "--bag",
            str(recorded),
            "--no-progress",
        ],
    )
    assert result.exit_code == 0, result.output
    topics = decoded(recorded)
    maps = len(topics["/map"])
    assert maps >= 3 and len(topics["/tf"]) == maps and len(topics["/guide/plan"]) >= 2
    assert Counter(m.ns for m in topics["/guide/graph"][0].markers) == Counter(ros.MARKER_NAMESPACES)
    grid = topics["/map"][-1]
    assert grid.info.resolution == pytest.approx(0.4) and set(np.unique(grid.data)) <= {-1, 0, 100}

    replayed = runner.invoke(
        app,
        [
            "bag",
            "--bag",
            str(recorded),
            "--out",
            str(tmp_path / "replay.mcap"),
            "--planner",
            "guide2=guide:candidates=2",
            "--protocol",
            "maze",
            "--no-progress",
        ],
    )
    assert replayed.exit_code == 0, replayed.output
    assert f"{maps} maps, {maps} plans;" in replayed.output
    again = decoded(tmp_path / "replay.mcap")
    assert len(again["/guide/plan"]) == len(again["/guide/decision"]) == maps
    assert any(len(m.markers[1].points) for m in again["/guide/graph"])  # guide's predicted nodes are drawn


def test_bad_bags_and_outputs_are_one_error_line(small_maze, tmp_path):
    write_slam_bag(tmp_path / "bag", small_maze, StoragePlugin.SQLITE3, maps=1)
    cases = [
        (["--bag", str(tmp_path / "none"), "--out", str(tmp_path / "o.mcap")], "no such bag"),
        (["--bag", str(tmp_path / "bag"), "--out", str(tmp_path / "o.txt")], "ends in .mcap"),
        (
            ["--bag", str(tmp_path / "bag"), "--out", str(tmp_path / "o.mcap"), "--map-topic", "/grid"],
            "no /grid topic; it has: /map, /tf",
        ),
        (
            ["--bag", str(tmp_path / "bag"), "--out", str(tmp_path / "o.mcap"), "--map-topic", "/tf"],
            "/tf holds tf2_msgs/msg/TFMessage, not nav_msgs/msg/OccupancyGrid",
        ),
        (["--bag", str(tmp_path / "bag"), "--out", str(tmp_path / "o.mcap"), "--protocol", "moon"], "--protocol"),
        (["--bag", str(tmp_path / "bag"), "--out", str(tmp_path / "o.mcap"), "--planner", "nope"], "nope"),
    ]
    for arguments, message in cases:
        result = runner.invoke(app, ["bag", "--no-progress", *arguments])
        assert result.exit_code == 2, (arguments, result.output)
        assert message in result.output and "Traceback" not in result.output, result.output
    result = runner.invoke(
        app,
        [
            "bag",
            "--bag",
            str(tmp_path / "bag"),
            "--out",
            str(tmp_path / "o.mcap"),
            "--planner",
            "greedy_utility",
            "--protocol",
            "maze",
            "--base-frame",
            "gripper",
            "--no-progress",
        ],
    )
    assert result.exit_code == 1 and "--base-frame" in result.output, result.output


def test_tf_tree_composes_a_chain_and_waits_for_a_missing_link():
    tree = ros.TfTree()
    tree.update(ros.tf_message(1.0, 0.0, math.pi / 2, 0.0, "odom", "base_link"))
    assert tree.pose() is None  # no map -> odom yet
    tree.update(ros.tf_message(10.0, 5.0, math.pi / 2, 0.0, "/map", "odom"))
    x, y, yaw = tree.pose()
    assert (x, y, yaw) == (pytest.approx(10.0), pytest.approx(6.0), pytest.approx(math.pi))
    tree.update(ros.tf_message(math.nan, 0.0, 0.0, 0.0, "map", "odom"))  # a bad transform is ignored
    assert tree.pose()[0] == pytest.approx(10.0)


def test_a_bag_saves_its_final_map_which_plans_import_takes(small_maze, tmp_path):
    from pipeline.world.maps import load_map

    write_slam_bag(tmp_path / "bag", small_maze, StoragePlugin.SQLITE3, maps=4)
    result = runner.invoke(
        app,
        [
            "bag",
            "--bag",
            str(tmp_path / "bag"),
            "--out",
            str(tmp_path / "o.mcap"),
            "--planner",
            "greedy_utility",
            "--protocol",
            "maze",
            "--no-progress",
            "--save-map",
            str(tmp_path / "saved"),
        ],
    )
    assert result.exit_code == 0, result.output
    assert f"wrote {tmp_path / 'saved' / 'map.yaml'}" in result.output
    imported = runner.invoke(
        app,
        [
            "plans",
            "import",
            str(tmp_path / "saved" / "map.yaml"),
            "--out",
            str(tmp_path / "plans"),
            "--cell-size",
            "0.4",
            "--licence",
            "our lab's own run",
        ],
    )
    assert imported.exit_code == 0, imported.output
    plan = load_map(tmp_path / "plans" / "map.yaml")
    assert plan.cell_size == pytest.approx(0.4) and 0 < plan.free_cell_count <= small_maze.free_cell_count
