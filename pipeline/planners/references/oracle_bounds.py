"""Oracle bounds: a planner given the ground truth in one place only, to measure what that place can win.

Each wraps an ordinary lattice planner (`base`, any registered non-oracle `GraphPlanner`, built
with the remaining options) and lets the ground truth decide one thing:

- `oracle_gate`: the base planner's sliver gate is the truth. A target passes when its scan on
  the ground truth would reveal at least `min_gain` cells the belief lacks (the label the
  learned gate is fitted to). With `veto=true` the learned gate still decides, and the truth
  only vetoes the slivers it passes. If a perfect gate cannot make a planner 10 % shorter than
  `greedy_utility`, no better gate can.
- `oracle_tail`: the base planner drives until at most `handover_cells` ground-truth free cells
  are still unknown, then the ground-truth `expert` finishes. It bounds what any better
  end-game can win.

A third does not wrap: `oracle_lookahead` is gated greedy that tries each of its `k` best
targets in a copy of the episode on the ground truth and steps toward the one that completes
soonest. It bounds what a model of the unseen map, good enough to simulate a few candidate
routes, could win.

They are diagnostics, never planners to deploy: `guide planners` marks them as oracles.
What they measure is in docs/results.md.
"""

from __future__ import annotations

import copy
import math
from typing import Annotated, cast

import numpy as np

from pipeline.common.config import config_dataclass, flag, satisfies, text, whole
from pipeline.models.sliver_gate import TrueGain
from pipeline.planners.baselines.frontier import GreedyUtilityConfig, GreedyUtilityPlanner
from pipeline.planners.config import PlannerConfig, option
from pipeline.planners.graph_planner import GraphPlanner
from pipeline.planners.references.coverage_planners import ExpertPlanner
from pipeline.planners.registry import make_planner, planner_config, register_planner
from pipeline.planners.wrapper import innermost
from pipeline.world.maps import GroundTruthMap
from pipeline.world.planner import Observation, OraclePlanner, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE
from pipeline.world.simulator import Episode

DEFAULT_BASE = "greedy_utility"


def _lattice_base(name: str) -> None:
    """UnknownPlannerError (a KeyError) for a name not registered, ValueError for an oracle or a
    planner without the lattice graph: what an oracle bound cannot wrap."""
    base = planner_config(name)
    if not base.lattice_planner:
        raise ValueError(f"{name} keeps no lattice graph")
    if base.uses_ground_truth:
        raise ValueError(f"{name} sees the ground truth")


@config_dataclass
class OracleWrapperConfig(PlannerConfig):
    """A bound that wraps a base planner: its own options, and the base's (passed on to it)."""

    uses_ground_truth = True
    lattice_planner = False
    objects = ("base_options",)  # the base planner's options, as given beside this config's

    base: Annotated[str, satisfies(_lattice_base, "a lattice planner that does not see the ground truth", text())] = (
        option(DEFAULT_BASE, "the lattice planner the ground truth helps (any that does not see the ground truth)")
    )

    @classmethod
    def base_planner(cls, options: dict) -> str:
        """The name of the base planner `options` ask for."""
        return options.get("base", DEFAULT_BASE)

    @classmethod
    def split(cls, options: dict) -> tuple[dict, dict, list[str]]:
        """Options this config does not take go to the base planner (checked when it is built)."""
        fields, objects, rest = super().split(options)
        objects = {**objects, "base_options": {**objects.get("base_options", {}), **{k: options[k] for k in rest}}}
        return fields, objects, []


class _OracleWrapper(OraclePlanner):
    """Delegates to `self.base`; subclasses add the ground truth where they need it."""

    uses_ground_truth = True

    def __init__(self, config: OracleWrapperConfig, base_options: dict | None = None):
        self.config = config
        self.base = make_planner(config.base, **(base_options or {}))
        self.trained_models = getattr(innermost(self.base), "trained_models", [])

    def check_protocol(self, protocol: Protocol) -> None:
        self.base.check_protocol(protocol)


class TrueGainGate:
    """A sliver gate that knows: passes the cells whose ground-truth scan reveals >= `min_gain`
    cells the belief lacks; with `learned`, only those the learned gate passes too (a veto)."""

    def __init__(self, true_gain: TrueGain, min_gain: int, learned=None):
        self.true_gain, self.min_gain, self.learned = true_gain, min_gain, learned

    def reach_cells(self, range_cells: float) -> int:
        """How far (cells, Chebyshev) from a candidate a belief change can move its verdict: the
        scan's reach, or the learned gate's when it vetoes."""
        reach = int(math.ceil(range_cells)) + 1
        return max(reach, self.learned.reach_cells(range_cells)) if self.learned is not None else reach

    def passes(
        self, belief: np.ndarray, cells: np.ndarray, range_cells: float, frontier: np.ndarray | None = None
    ) -> np.ndarray:
        big = self.true_gain.gains(belief, cells) >= self.min_gain
        if self.learned is not None:
            big &= self.learned.passes(belief, cells, range_cells, frontier)
        return big


@config_dataclass
class OracleGateConfig(OracleWrapperConfig):
    description = (
        "oracle bound: the base planner (base=) with a ground-truth sliver gate (true gain >= min_gain; "
        "veto=true: vetoes the learned gate's slivers)"
    )

    min_gain: Annotated[int, whole(1, note="cells")] = option(
        50,
        "cells: a target passes when its scan on the ground truth would "
        "reveal this many the belief lacks (the label the learned gate is "
        "fitted to)",
    )
    veto: Annotated[bool, flag()] = option(
        False, "the learned gate still decides, and the truth only vetoes the slivers it passes"
    )


@register_planner("oracle_gate", OracleGateConfig)
class OracleGatePlanner(_OracleWrapper):
    """Oracle bound: `base` (default greedy_utility) with the ground truth as its sliver gate."""

    description = OracleGateConfig.description

    def __init__(self, config: OracleGateConfig = OracleGateConfig(), base_options: dict | None = None):
        options, base, min_gain, veto = dict(base_options or {}), config.base, config.min_gain, config.veto
        if veto:
            if options.get("sliver_gate", True) is not True:  # an option of the base planner, beside this config
                raise ValueError("veto=true vetoes the learned gate's slivers: drop sliver_gate=false")
            options = {**options, "sliver_gate": True}
        super().__init__(config, options)
        self.min_gain, self.veto = int(min_gain), veto
        # the learned gate the truth vetoes
        self.learned = cast(GraphPlanner, innermost(self.base)).gate if veto else None
        self.description = f"{self.description} [base {base}: {self.base.description}]"

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:  # type: ignore[override]  # an oracle: reset with the map itself
        self.base.reset(ground_truth.frame, protocol, seed)
        cast(GraphPlanner, innermost(self.base)).gate = TrueGainGate(
            TrueGain(ground_truth, protocol), self.min_gain, self.learned
        )

    def plan(self, observation: Observation) -> list[Waypoint]:
        return self.base.plan(observation)


@config_dataclass
class OracleTailConfig(OracleWrapperConfig):
    description = (
        "oracle bound: the base planner (base=) until handover_cells ground-truth free cells are unknown, "
        "then the ground-truth expert"
    )

    handover_cells: Annotated[int, whole(0)] = option(
        8000, "ground-truth free cells still unknown when the expert takes over"
    )


@register_planner("oracle_tail", OracleTailConfig)
class OracleTailPlanner(_OracleWrapper):
    """Oracle bound: `base` (default greedy_utility) until `handover_cells` unknown free cells, then `expert`."""

    description = OracleTailConfig.description

    def __init__(self, config: OracleTailConfig = OracleTailConfig(), base_options: dict | None = None):
        super().__init__(config, base_options)
        base, handover_cells = config.base, config.handover_cells
        self.handover_cells = int(handover_cells)
        self.expert = ExpertPlanner()
        self.description = f"{self.description} [base {base}: {self.base.description}]"

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:  # type: ignore[override]  # an oracle: reset with the map itself
        self.base.reset(ground_truth.frame, protocol, seed)
        self.expert.reset(ground_truth, protocol, seed)
        self.free_cells = int(ground_truth.free.sum())
        self.handed_over = False

    def plan(self, observation: Observation) -> list[Waypoint]:
        if not self.handed_over:
            unknown = self.free_cells - int(np.count_nonzero(observation.belief == FREE))
            self.handed_over = unknown <= self.handover_cells
        if self.handed_over:
            return self.expert.plan(observation)
        self.expert.update_graph(observation)  # its lattice graph folds in changes incrementally
        return self.base.plan(observation)


@config_dataclass
class OracleLookaheadConfig(GreedyUtilityConfig):
    description = (
        "oracle bound: gated greedy whose k best targets are each run to completion in a copy of the "
        "episode on the ground truth; one step toward the one that completes soonest"
    )
    uses_ground_truth = True

    sliver_gate: Annotated[bool, flag()] = option(
        True, GreedyUtilityConfig.__dataclass_fields__["sliver_gate"].metadata["help"]
    )
    k: Annotated[int, whole(1)] = option(
        3, "gated greedy's best targets tried on the ground truth; 1 = gated greedy itself"
    )


@register_planner("oracle_lookahead", OracleLookaheadConfig)
class OracleLookaheadPlanner(GreedyUtilityPlanner):
    """Oracle bound: gated greedy with a one-step lookahead on the ground truth.

    At each decision its `k` best targets (utility per metre) are each tried in a copy of the
    episode run on the ground truth: head for the target until it is reached or stops being a
    target, then gated greedy to completion. The robot takes one step toward the target whose
    copy completed soonest and decides again. `k=1` is gated greedy itself.
    """

    uses_ground_truth = True
    description = OracleLookaheadConfig.description

    def __init__(self, config: OracleLookaheadConfig = OracleLookaheadConfig()):
        super().__init__(config)
        k = config.k
        self.k = int(k)

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:  # type: ignore[override]  # an oracle: reset with the map itself
        super().reset(ground_truth.frame, protocol, seed)
        self.shadow = Episode(ground_truth, protocol)  # the real episode, mirrored move by move
        self.shadow.observe()

    def plan(self, observation: Observation) -> list[Waypoint]:
        if np.hypot(*np.subtract(observation.position, self.shadow.position)) > 1e-9:
            self.shadow.move(observation.position)
            self.shadow.observe()
        pred, ranked = self.ranked_targets(observation)
        if ranked.size == 0:
            return []
        choice = int(ranked[0])
        if self.k > 1 and ranked.size > 1:
            shared = (self.shadow.map, self.shadow.lidar, self.gate)  # read-only: not copied
            best = np.inf
            for target in ranked[: self.k]:
                trial = copy.deepcopy(self, {id(obj): obj for obj in shared})
                distance = trial.finish_in_copy(int(target), pred)
                if distance < best:
                    best, choice = distance, int(target)
        assert self.graph is not None
        return self.waypoints_along(self.graph.path_from_predecessors(pred, choice))

    def finish_in_copy(self, target: int, pred: np.ndarray) -> float:
        """On a copy: head for `target`, then gated greedy; the distance at completion (inf: none)."""
        distance = self.finish_episode(self.shadow, target, pred)
        return np.inf if distance is None else distance
