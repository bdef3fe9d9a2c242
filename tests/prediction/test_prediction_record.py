"""The record of checked predictions (prediction/prediction_trust.py): precision, base rate, lift, trust."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.lattice.graph import NODE_FREE, NODE_OCCUPIED, NODE_UNKNOWN
from pipeline.prediction.prediction_trust import PredictionRecord, PredictionTrustConfig, trusted_threshold

U, F, X = NODE_UNKNOWN, NODE_FREE, NODE_OCCUPIED


def test_predicted_nodes_are_scored_once_when_observed_and_the_base_rate_counts_every_unknown_node():
    record = PredictionRecord(PredictionTrustConfig(prior_nodes=1e-6))
    record.check(np.array([U, U, U, U, F]))
    record.remember(np.array([True, True, True, True, False]), np.array([0, 1]))  # 0 and 1 predicted free
    record.check(np.array([F, X, X, U, F]))  # 0 right, 1 wrong; 2 seen occupied (not predicted)
    assert (record.right, record.wrong, record.seen_free, record.seen_occupied) == (1, 1, 1, 2)
    record.check(np.array([F, X, X, F, F]))  # nothing predicted is pending; node 3 adds to the base
    assert (record.right, record.wrong, record.seen_free, record.seen_occupied) == (1, 1, 2, 2)
    assert record.precision == pytest.approx(0.5) and record.base == pytest.approx(0.5) and abs(record.lift) < 1e-5


def test_trust_follows_the_lift_over_the_base_rate():
    config = PredictionTrustConfig(prior_nodes=1e-6, full_at=0.5, none_at=0.1)
    record = PredictionRecord(config)
    record.right, record.wrong, record.seen_free, record.seen_occupied = 90, 10, 90, 10
    assert abs(record.lift) < 1e-5 and record.trust == 0.0  # calling everything free scores the same
    record.right, record.wrong, record.seen_free, record.seen_occupied = 95, 5, 50, 50
    assert record.lift == pytest.approx(0.9, abs=1e-5) and record.trust == 1.0
    record.right, record.wrong = 70, 30  # precision 0.7 over a base of 0.5: lift 0.4
    assert record.trust == pytest.approx(0.75, abs=1e-5)
    state = record.state()
    fresh = PredictionRecord(config)
    fresh.restore(state)
    assert fresh.state() == state and state.as_dict()["trust"] == pytest.approx(0.75)
    fresh.reset()
    assert fresh.right == fresh.wrong == 0
    assert trusted_threshold(0.8, 1.0) == 0.8 and trusted_threshold(0.8, 0.0) == 1.0
    with pytest.raises(ValueError, match="none_at"):
        PredictionTrustConfig(full_at=0.1, none_at=0.2)
