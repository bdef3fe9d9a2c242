"""What the simulator and every planner share: the observation before a decision and the planner interface."""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import cast

import numpy as np

from pipeline.world.maps import GroundTruthMap, MapFrame
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

    `reset` is called once per episode with the map's frame (its extent, cell size and start),
    what a robot knows before it explores: a planner decides from that and the observations
    alone. Only an oracle (`OraclePlanner`, `uses_ground_truth = True`) is reset with the
    ground-truth map.
    """

    name: str = ""
    description: str = ""
    uses_ground_truth: bool = False
    ignores_motion_rule: bool = False  # only the ground-truth "Optimal" reference may set this
    needs_policy: bool = False  # True: needs a trained diffusion policy (models/ or the shipped default)
    # How far a predicting planner leans on its predictions at its last decision (0-1, from the
    # record of its checked predictions); None for a planner that keeps no such record.
    prediction_trust: float | None = None

    @abstractmethod
    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        """Prepare for a new episode on a map of this frame."""

    @abstractmethod
    def plan(self, observation: Observation) -> list[Waypoint]:
        """Next lattice waypoints in world metres; [] when nothing reachable is left to explore."""

    def check_protocol(self, protocol: Protocol) -> None:
        """Warn (`ProtocolMismatchWarning`) when a trained model of this planner was trained at other
        protocol values than `protocol`; planners without trained models have nothing to say."""


class OraclePlanner(Planner):
    """A planner that sees the ground truth (a reference or a bound): reset with the map itself."""

    uses_ground_truth = True

    @abstractmethod
    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:  # type: ignore[override]
        """Prepare for a new episode on `ground_truth`."""


def reset_planner(planner: Planner, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
    """Reset `planner` for an episode on `ground_truth`: an oracle gets the map, any other its frame only."""
    oracle = bool(getattr(planner, "uses_ground_truth", False))
    # An oracle's reset takes the map itself.
    planner.reset(cast(MapFrame, ground_truth) if oracle else ground_truth.frame, protocol, seed)
