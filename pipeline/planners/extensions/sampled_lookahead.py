"""`sampled_lookahead`: gated greedy that looks one choice ahead on maps it imagines.

`oracle_lookahead` tries each of gated greedy's best targets in a copy of the episode on the
ground truth; this planner does the same without the ground truth. At each decision the block model (`pipeline.models.modeling_block_model`)
gives P(free) of every 5 m maze block from what has been seen; `samples` block maps are drawn
from those probabilities, each cut to `horizon_m` beyond the known free space (a model sees
no further with any use). On each drawn map, each of the `k` best targets
(utility per metre) is tried: head for it until it is reached or stops being a target, then
gated greedy until that map is explored. The robot steps toward the target whose rollouts are
shortest on average and decides again. `k=1` is gated greedy itself.

With `switch_margin_m` set, the last decision's target stays among the candidates while it is
still a target, and the robot leaves it only for one whose mean rollout is shorter by more than
that margin: fresh maps are drawn at every decision, and without it the sampling noise alone can
turn the robot back and forth between two targets.

With `exit_weight` set, each rollout's cost also counts that weight times the way (through the
drawn map) from where the rollout ended to the nearest cell beside the horizon cut, where the
drawn free space goes on: the cut map is explored when a rollout ends, the real one is not, and
a rollout that ends far from what is left has a walk back the cut map does not charge.

With `workers=2` a second, forked process (`pipeline.planners.extensions.rollout_worker`) takes rollouts
from the same job counter as this one: the same costs and routes, in less time on a machine
with two free cores.

With `temperature` T the maps are drawn from sigmoid(logit / T): the shipped model is
overconfident, yet softer draws made routes no shorter, since every target is rolled out on
the same maps. Both options stay off.
`BlockLookahead` (`pipeline.planners.extensions.lookahead`) is the simulator on its own, which
`guide:lookahead=K` uses too.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np

from pipeline.common.config import config_dataclass, flag, maybe, positive, real, text, whole
from pipeline.models.defaults import block_model_for
from pipeline.models.modeling_block_model import BlockModel
from pipeline.planners.baselines.frontier import GreedyUtilityConfig, GreedyUtilityPlanner
from pipeline.planners.config import option
from pipeline.planners.extensions.lookahead import WORKERS_NOTE, BlockLookahead
from pipeline.planners.registry import register_planner
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.protocol import Protocol


@config_dataclass
class SampledLookaheadConfig(GreedyUtilityConfig):
    description = (
        "gated greedy whose k best targets are each run to completion on maps drawn from the learned "
        "block model; one step toward the one whose rollouts are shortest"
    )
    objects = ("model",)  # an injected block model
    renamed = {"checkpoint": "block_model_file"}

    sliver_gate: Annotated[bool, flag()] = option(
        True, GreedyUtilityConfig.__dataclass_fields__["sliver_gate"].metadata["help"]
    )
    k: Annotated[int, whole(1)] = option(
        3, "gated greedy's best targets (utility per metre) rolled out; 1 = gated greedy itself"
    )
    samples: Annotated[int, whole(1)] = option(
        4, "block maps drawn from the block model per decision; each target is rolled out on each"
    )
    horizon_m: Annotated[float, real(0.0, note="metres")] = option(
        20.0, "metres: the drawn maps are cut this far beyond the known free space"
    )
    block_model_file: Annotated[str | None, maybe(text())] = option(
        None, "the block model [default: models/block_model/block_model.pt, else the shipped one]"
    )
    switch_margin_m: Annotated[float | None, maybe(real(0.0, note="metres"), "off")] = option(
        None, "metres: leave the last target only for one whose mean rollout is shorter by more (None: off)"
    )
    exit_weight: Annotated[float, real(0.0)] = option(
        0.0, "weight of each rollout's way back to the horizon cut (0 = off)"
    )
    temperature: Annotated[float, positive()] = option(1.0, "maps are drawn from sigmoid(logit / temperature)")
    workers: Annotated[int, whole(1, 2, note=WORKERS_NOTE)] = option(
        1, "2: the rollouts shared with a forked second process (the same costs and routes)"
    )

    def model_slots(self) -> dict[str, str]:
        return {**super().model_slots(), "block_model_file": "block_model"}


@register_planner("sampled_lookahead", SampledLookaheadConfig)
class SampledLookaheadPlanner(GreedyUtilityPlanner):
    """Gated greedy whose k best targets are each rolled out on block maps drawn from the block model."""

    description = SampledLookaheadConfig.description

    def __init__(self, config: SampledLookaheadConfig = SampledLookaheadConfig(), model: BlockModel | None = None):
        super().__init__(config)
        k, samples, horizon_m, checkpoint = config.k, config.samples, config.horizon_m, config.block_model_file
        switch_margin_m = None if config.switch_margin_m is None else float(config.switch_margin_m)
        exit_weight, temperature, workers = config.exit_weight, config.temperature, config.workers
        self.k, self.switch_margin_m = int(k), switch_margin_m
        model, self.model_source = block_model_for(checkpoint, model)
        self.model = model
        self.lookahead = BlockLookahead(model, samples, horizon_m, exit_weight, temperature, workers=workers)
        self.description = f"{type(self).description} [{self.model_source}; {self.gate_source}]"

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        super().reset(frame, protocol, seed)
        self.lookahead.reset(frame)
        self.last_target: int | None = None

    def plan(self, observation: Observation) -> list[Waypoint]:
        pred, ranked = self.ranked_targets(observation)
        if ranked.size == 0:
            return []
        choice = int(ranked[0])
        if self.k > 1 and ranked.size > 1:
            candidates = [int(t) for t in ranked[: self.k]]
            incumbent = 0  # the candidate a challenger must beat by the margin
            if (
                self.switch_margin_m is not None
                and self.last_target is not None
                and self.last_target in set(ranked.tolist())
            ):
                if self.last_target not in candidates:
                    candidates.append(self.last_target)
                incumbent = candidates.index(self.last_target)
            cost = self.lookahead.costs(self, observation, candidates, pred, self.rng)
            best = int(np.argmin(cost))
            if self.switch_margin_m is not None and cost[best] >= cost[incumbent] - self.switch_margin_m:
                best = incumbent
            choice = candidates[best]
        self.last_target = choice
        assert self.graph is not None
        return self.waypoints_along(self.graph.path_from_predecessors(pred, choice))
