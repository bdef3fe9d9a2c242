"""The stall hand-over (ours, not the paper's): after `stall_steps` moves that reveal nothing,
one step toward the nearest useful node instead of the policy's.

A policy trained on few episodes can circle in explored space, each of its moves feasible and
none of them useful. The paper's planner never notices. This wrapper counts the moves since
the belief last gained a free cell and, from `stall_steps` on, hands each decision to Yamauchi's
rule (one step along the shortest known path to the nearest useful node) until news arrives.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np

from pipeline.common.config import config_dataclass, whole
from pipeline.planners.config import PlannerConfig, option
from pipeline.planners.guide.guide import GuidePlanner
from pipeline.planners.wrapper import PlannerWrapper
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE


@config_dataclass
class StallHandoverConfig(PlannerConfig):
    part = "the stall hand-over (ours, mode policy)"

    stall_steps: Annotated[int, whole(1)] = option(
        3, "mode policy: after this many moves that reveal nothing, one step toward the nearest useful node instead"
    )


class StallHandover(PlannerWrapper):
    """GUIDE's policy (`GuidePlanner`, or a wrapper of it), handed over to the nearest useful node
    while `stall_steps` or more moves in a row have revealed no free cell."""

    inner: GuidePlanner

    def __init__(self, inner: GuidePlanner, stall_steps: int):
        super().__init__(inner)
        self.stall_steps = int(stall_steps)
        self.moves_without_news = 0

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        super().reset(frame, protocol, seed)
        self.moves_without_news = 0

    def plan(self, observation: Observation) -> list[Waypoint]:
        if not self.inner.perceive(observation):
            return []  # nothing reachable is left to explore
        changed = observation.changed
        news = changed is None or bool(np.any(observation.belief.reshape(-1)[changed] == FREE))
        self.moves_without_news = 0 if news else self.moves_without_news + 1
        if self.moves_without_news < self.stall_steps:
            return self.inner.select_action()
        return self.inner.hand_over()
