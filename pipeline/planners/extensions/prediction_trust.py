"""Trust in predictions (ours, not the paper's): a predicting planner that leans on its predicted
nodes only as far as they have been right.

The paper's planner believes its inpainter wherever it runs. Trained on floors unlike the
building it explores, the inpainter predicts rooms that are not there, and the planner walks
into them. This wrapper swaps the planner's node predictor for a `TrustedPredictor`
(`pipeline.prediction.prediction_trust`): every decision it scores the predicted nodes the
robot has since observed against the base rate of free nodes in the unknown, and hands the
planner fewer, surer predictions as their lift over that base rate falls, none at all (the
observed graph only, `dare`'s) when it falls to `trust_none`. It wraps `guide`,
`guide_noregion`, `guide_tsp` and `mapex`; their configs take its options.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Annotated, cast

from pipeline.common.config import config_dataclass, flag, real
from pipeline.planners.config import PlannerConfig, option
from pipeline.planners.wrapper import PlannerWrapper, innermost
from pipeline.prediction.prediction_trust import PredictionTrustConfig, TrustedPredictor, TrustState
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Planner
from pipeline.world.protocol import Protocol

if TYPE_CHECKING:
    from pipeline.planners.predicting import PredictingPlanner
    from pipeline.prediction.node_predictor import NodePredictor


@config_dataclass
class PredictionTrustOptions(PlannerConfig):
    part = "trust in the predictions (ours)"

    trust: Annotated[bool, flag()] = option(
        True,
        "lean on predictions only as far as they have been right: their lift over the base "
        "rate of free nodes among the nodes seen since (off: believe them in full)",
    )
    trust_full: Annotated[float, real(-1.0, 1.0)] = option(
        PredictionTrustConfig.full_at, "lift over the base rate at or above which predictions are used in full"
    )
    trust_none: Annotated[float, real(-1.0, 1.0)] = option(
        PredictionTrustConfig.none_at, "lift at or below which no prediction is used (the observed graph only)"
    )

    def check(self) -> None:
        if not self.trust_none < self.trust_full:
            raise ValueError(f"trust_none ({self.trust_none}) must be below trust_full ({self.trust_full})")
        super().check()


class TrustingPlanner(PlannerWrapper):
    """A predicting planner (or a wrapper of one) whose node predictor is a `TrustedPredictor`."""

    def __init__(self, inner: Planner, config: PredictionTrustConfig):
        super().__init__(inner)
        base = cast("PredictingPlanner", innermost(inner))  # `with_trust` wraps only a planner that predicts
        self.trusted = TrustedPredictor(cast("NodePredictor", base.predictor), config)
        base.predictor = self.trusted
        self.description = (
            f"{inner.description} [trust in predictions: in full at a lift of {config.full_at:g} over "
            f"the base rate, none at {config.none_at:g}]"
        )

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        self.inner.reset(frame, protocol, seed)
        self.trusted.reset()

    @property
    def prediction_trust(self) -> float:  # type: ignore[override]  # read-only: the record's trust
        return self.trusted.record.trust

    @property
    def trust_state(self) -> TrustState:
        """The record of checked predictions, for decision records and a robot session's state."""
        return self.trusted.record.state()

    def restore_trust(self, state: TrustState) -> None:
        """Carry a record over a reset in the same building (a robot session's new map frame)."""
        self.trusted.record.restore(state)


def with_trust(planner: Planner, options: PredictionTrustOptions) -> Planner:
    """`planner` wrapped in a `TrustingPlanner` when `options.trust` is on and it predicts at all
    (`dare`'s observed graph and a planner without an inpainter have nothing to trust)."""
    if not options.trust or getattr(innermost(planner), "predictor", None) is None:
        return planner
    return TrustingPlanner(planner, PredictionTrustConfig(full_at=options.trust_full, none_at=options.trust_none))
