"""Trust in predictions, kept online: how many of the predicted free nodes the robot has since
observed were right, and how far a planner leans on its predictions because of it.

An inpainter trained on tidy floors predicts free space where a real building has walls, and
a planner that trusts such predictions walks into rooms that are not there. The record here
needs no ground truth: a node predicted free at some decision that the robot has since
observed is right when it was seen free and wrong when seen occupied. Precision alone does not
say whether the predictions help: where most of the unknown is free, predicting everything
free is mostly right and tells the planner nothing. So the record also counts every node that
was unknown in the model's input at a decision and has since been observed (the base rate of free nodes in the
unknown), and the trust comes from the lift of the predictions over that base rate:
lift = (precision - base) / (1 - base), 1 for a model never wrong, 0 for one no better than
calling everything free. Both rates carry a Beta prior, so that a few early nodes do not swing
them. The lift maps to a trust in [0, 1]: full at or above `full_at`, none at or below
`none_at`, linear between.

`TrustedPredictor` wraps a `NodePredictor`: it keeps the record of what the model predicts (at
its own threshold, whatever the trust, so that the record keeps learning while predictions are
set aside) and hands the planner only as much as the trust allows. Trust t raises each
threshold tau to tau + (1 - t)(1 - tau): fewer, surer predicted nodes enter the graph, and
fewer count towards the utility boost; at t = 0 none do, and the planner plans on the observed
graph alone (`dare`'s).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.lattice.graph import NODE_FREE, NODE_OCCUPIED, NODE_UNKNOWN, LatticeGraph, node_states_in
from pipeline.prediction.node_image import observed_node_states
from pipeline.prediction.node_predictor import NodePredictor


@dataclass(frozen=True)
class PredictionTrustConfig:
    """How the record of checked predictions becomes a trust in [0, 1]."""

    prior_nodes: float = 20.0  # the priors' weight, in nodes: the record starts as if this many had been seen
    prior_precision: float = 0.9  # the predictions' precision before any is checked
    prior_base: float = 0.5  # the unknown's free share before any node is seen
    # Predictions no better than the base rate still point the planner at large unknown space, and
    # on generated building floors, where walls on lattice nodes leave every inpainter near the
    # base rate, believing them in full made routes shorter than cutting them. So the cut is kept for predictions worse than the base rate.
    full_at: float = 0.0  # lift at or above which predictions are used in full
    none_at: float = -0.2  # lift at or below which none are used (the observed graph only)

    def __post_init__(self) -> None:
        if not self.prior_nodes > 0 or not 0 < self.prior_precision < 1 or not 0 < self.prior_base < 1:
            raise ValueError(
                f"PredictionTrustConfig: need prior_nodes > 0 and priors strictly between 0 and 1, got "
                f"{self.prior_nodes}, {self.prior_precision}, {self.prior_base}"
            )
        if not -1 <= self.none_at < self.full_at <= 1:
            raise ValueError(
                f"PredictionTrustConfig: need -1 <= none_at < full_at <= 1, got none_at={self.none_at}, "
                f"full_at={self.full_at}"
            )


@dataclass(frozen=True)
class TrustState:
    """A record at one moment: what a decision's record and a robot session keep."""

    right: int  # predicted free, seen free
    wrong: int  # predicted free, seen occupied
    seen_free: int  # unknown at a decision, seen free since (predicted or not)
    seen_occupied: int
    precision: float
    base: float
    lift: float
    trust: float

    def as_dict(self) -> dict[str, float | int]:
        return {
            "right": self.right,
            "wrong": self.wrong,
            "seen_free": self.seen_free,
            "seen_occupied": self.seen_occupied,
            "precision": round(self.precision, 4),
            "base": round(self.base, 4),
            "lift": round(self.lift, 4),
            "trust": round(self.trust, 4),
        }


class PredictionRecord:
    """The predicted free nodes waiting to be observed, and how many observed ones were right."""

    def __init__(self, config: PredictionTrustConfig = PredictionTrustConfig()):
        self.config = config
        self.right = self.wrong = self.seen_free = self.seen_occupied = 0
        self.pending = np.zeros(0, dtype=bool)  # predicted free at a decision, not yet observed
        self.unknown = np.zeros(0, dtype=bool)  # unknown at the last decision

    def reset(self, keep_counts: bool = False) -> None:
        """A new graph: nothing pending; the counts too unless `keep_counts` (a robot session
        whose map frame changed is still in the same building)."""
        self.pending = np.zeros(0, dtype=bool)
        self.unknown = np.zeros(0, dtype=bool)
        if not keep_counts:
            self.right = self.wrong = self.seen_free = self.seen_occupied = 0

    def check(self, observed: np.ndarray) -> None:
        """Score the nodes observed since the last decision (`observed`: every lattice node's state
        as seen at its own cell)."""
        if self.pending.size != observed.size:  # a new lattice: nothing remembered holds
            self.pending = np.zeros(observed.size, dtype=bool)
            self.unknown = np.zeros(observed.size, dtype=bool)
        free, occupied = observed == NODE_FREE, observed == NODE_OCCUPIED
        self.right += int((self.pending & free).sum())
        self.wrong += int((self.pending & occupied).sum())
        self.seen_free += int((self.unknown & free).sum())
        self.seen_occupied += int((self.unknown & occupied).sum())
        self.pending &= ~(free | occupied)
        self.unknown &= ~(free | occupied)

    def remember(self, asked: np.ndarray, predicted: np.ndarray) -> None:
        """The nodes the model was asked about now (unknown in its input image: a boolean per
        node) and those it predicted free, to be scored when observed."""
        self.unknown = np.asarray(asked, dtype=bool).copy()
        self.pending[np.asarray(predicted, dtype=np.int64)] = True

    @property
    def precision(self) -> float:
        """The share of checked predicted nodes seen free, with the prior."""
        c = self.config
        return (self.right + c.prior_nodes * c.prior_precision) / (self.right + self.wrong + c.prior_nodes)

    @property
    def base(self) -> float:
        """The share of once-unknown nodes seen free, with the prior: what calling everything free scores."""
        c = self.config
        return (self.seen_free + c.prior_nodes * c.prior_base) / (self.seen_free + self.seen_occupied + c.prior_nodes)

    @property
    def lift(self) -> float:
        """(precision - base) / (1 - base): 1 for predictions never wrong, 0 for no better than the base rate."""
        base = self.base
        return (self.precision - base) / max(1.0 - base, 1e-9)

    @property
    def trust(self) -> float:
        c = self.config
        return float(np.clip((self.lift - c.none_at) / (c.full_at - c.none_at), 0.0, 1.0))

    def state(self) -> TrustState:
        return TrustState(
            self.right, self.wrong, self.seen_free, self.seen_occupied, self.precision, self.base, self.lift, self.trust
        )

    def restore(self, state: TrustState) -> None:
        """Take the counts of an earlier record (a session's planner rebuilt on a new frame)."""
        self.right, self.wrong = int(state.right), int(state.wrong)
        self.seen_free, self.seen_occupied = int(state.seen_free), int(state.seen_occupied)


def trusted_threshold(threshold: float, trust: float) -> float:
    """tau raised towards 1 as trust falls: tau + (1 - trust)(1 - tau)."""
    return threshold + (1.0 - trust) * (1.0 - threshold)


class TrustedPredictor:
    """A `NodePredictor` whose predictions the planner gets only as far as they have been right."""

    def __init__(self, inner: NodePredictor, config: PredictionTrustConfig = PredictionTrustConfig()):
        self.inner = inner
        self.config = inner.config  # the thresholds, as the planner reads them
        self.record = PredictionRecord(config)

    def reset(self, keep_counts: bool = False) -> None:
        self.record.reset(keep_counts)

    def probabilities(self, graph: LatticeGraph, states: np.ndarray | None = None) -> np.ndarray:
        return self.inner.probabilities(graph, states)

    def _observe(self, graph: LatticeGraph) -> tuple[np.ndarray, np.ndarray, float]:
        """Score what was predicted before, then predict: (states, probabilities, trust)."""
        self.record.check(node_states_in(graph.belief, graph.node_flat))
        states = observed_node_states(graph.belief, graph)
        probability = self.inner.probabilities(graph, states)
        self.record.remember(
            states == NODE_UNKNOWN, self.inner.above(graph, states, probability, self.config.threshold)
        )
        return states, probability, self.record.trust

    def _at_trust(
        self, graph: LatticeGraph, states: np.ndarray, probability: np.ndarray, tau: float, trust: float
    ) -> np.ndarray:
        if trust <= 0.0:
            return np.zeros(0, dtype=np.int64)
        return self.inner.above(graph, states, probability, trusted_threshold(tau, trust))

    def predict(self, graph: LatticeGraph) -> np.ndarray:
        states, probability, trust = self._observe(graph)
        return self._at_trust(graph, states, probability, self.config.threshold, trust)

    def predict_with_counted(self, graph: LatticeGraph) -> tuple[np.ndarray, np.ndarray]:
        states, probability, trust = self._observe(graph)
        predicted = self._at_trust(graph, states, probability, self.config.threshold, trust)
        count_tau = self.config.count_threshold
        if count_tau is None or count_tau == self.config.threshold:
            return predicted, predicted
        return predicted, self._at_trust(graph, states, probability, count_tau, trust)
