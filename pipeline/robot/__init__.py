"""GUIDE on a robot: the planners on a live SLAM map and pose (`ExplorationSession`)."""

from pipeline.robot.occupancy_grid import GridMessage
from pipeline.robot.session import ExplorationSession, Plan

__all__ = ["ExplorationSession", "GridMessage", "Plan"]
