"""Uncoordinated teams: every robot runs its own single-robot planner on its own belief.

The robots share what they see (through the team's belief) but not what they intend: each
planner is blind to its teammates, so two robots may chase the same frontier. This is the
baseline a coordinated team is measured against.
"""

from __future__ import annotations

from typing import Any

from pipeline.planners.registry import make_config, make_planner
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Planner, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.team import TeamObservation, TeamPlanner


class UncoordinatedTeam(TeamPlanner):
    """One `base` planner per robot (built with `options`), each reset and asked on its own."""

    def __init__(self, base: str, options: dict[str, Any] | None = None):
        self.base, self.options = base, dict(options or {})
        config, _ = make_config(base, **self.options)  # refuse bad options now, before an episode
        if config.uses_ground_truth:
            raise ValueError(f"{base} sees the ground truth: an oracle has its own team version or none")
        self.description = f"every robot runs its own {base}, blind to the others"
        self.planners: list[Planner] = []

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int, robots: int) -> None:
        if len(self.planners) != robots:
            self.planners = [make_planner(self.base, **self.options) for _ in range(robots)]
        for k, planner in enumerate(self.planners):
            planner.reset(frame, protocol, seed * 1009 + k)

    def plan(self, observation: TeamObservation) -> list[Waypoint]:
        return self.planners[observation.robot].plan(observation.observation)

    def check_protocol(self, protocol: Protocol) -> None:
        if self.planners:
            self.planners[0].check_protocol(protocol)
        else:
            make_planner(self.base, **self.options).check_protocol(protocol)
