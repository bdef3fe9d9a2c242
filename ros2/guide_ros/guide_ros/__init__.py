"""GUIDE on a ROS 2 robot: `explorer` wraps `pipeline.robot.ExplorationSession` in a node."""
