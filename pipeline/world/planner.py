"""What the simulator and every planner share: the observation before a decision and the planner interface."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol

Waypoint = tuple[float, float]


@dataclass(frozen=True)
class Observation:
    """What a planner sees before a decision. `belief` must be treated as read-only."""

    belief: np.ndarray
    position: tuple[float, float]  # world metres
    cell: tuple[int, int]  # (col, row)
    changed: np.ndarray | None  # flat cells changed since the previous decision; None = first
    step: int



class Planner(ABC):
    """Proposes the next waypoint(s); the simulator moves there in order, sensing after each.

    `reset` is called once per episode with the ground truth, which only oracle planners
    may look at (`uses_ground_truth = True`); every other planner must decide from the
    observation alone.
    """

    name: str = ""
    description: str = ""
    uses_ground_truth: bool = False
    ignores_motion_rule: bool = False  # only the ground-truth "Optimal" reference may set this
    needs_policy: bool = False  # True: needs a trained diffusion policy (models/ or the shipped default)

    @abstractmethod
    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        """Prepare for a new episode."""

    @abstractmethod
    def plan(self, observation: Observation) -> list[Waypoint]:
        """Next lattice waypoints in world metres; [] when nothing reachable is left to explore."""

    def check_protocol(self, protocol: Protocol) -> None:
        """Warn (`ProtocolMismatchWarning`) when a trained model of this planner was trained at other
        protocol values than `protocol`; planners without trained models have nothing to say."""
