"""What each robot of a coordinated team knows of its teammates' goals.

A coordinated team planner decides for one robot at a time, one lattice step a decision, so the
target a `TeamObservation` carries for a teammate (the last waypoint of its plan) is only its
next node. What coordination needs is the frontier node each teammate is heading for: its goal.
`HeardGoals` keeps every robot's goal and passes it on the links the episode reports: when a
robot decides, it hears the current goal of every teammate it is connected to then, and those
teammates hear its new goal. With full communication every robot always knows every goal; under
a range a robot knows a cut-off teammate's goal as of their last contact at a decision.
Goals are lattice node ids: every robot's lattice graph is built on the same map frame.
"""

from __future__ import annotations

from pipeline.world.team import TeamObservation


class HeardGoals:
    """Each robot's current goal node (None while it has none) and what each robot last heard of the others'."""

    def __init__(self, robots: int):
        self.goals: list[int | None] = [None] * robots
        self.heard: list[list[int | None]] = [[None] * robots for _ in range(robots)]

    def teammates_goals(self, observation: TeamObservation) -> list[int | None]:
        """Before robot `observation.robot` decides: its teammates' goals as it knows them (its own entry None)."""
        me = observation.robot
        for other, linked in enumerate(observation.connected):
            if linked:
                self.heard[me][other] = self.goals[other]
        return [None if other == me else goal for other, goal in enumerate(self.heard[me])]

    def decided(self, observation: TeamObservation, goal: int | None) -> None:
        """Robot `observation.robot` now heads for `goal` (None: it waits); its connected teammates hear so."""
        me = observation.robot
        self.goals[me] = goal
        for other, linked in enumerate(observation.connected):
            if linked:
                self.heard[other][me] = goal
