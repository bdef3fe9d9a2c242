"""The sliver gate: its counts, its fit, its file, and the shipped gate on a hand-made belief."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline.models.defaults import SHIPPED_GATE, resolve_gate_path
from pipeline.models.sliver_gate import (
    FEATURES,
    SliverGate,
    fit_sliver_gate,
    gate_features,
    load_gate,
    roc_auc,
    save_gate,
)
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN

RANGE_CELLS = 50.0  # 20 m at 0.4 m cells


def corridor_belief() -> np.ndarray:
    """A known corridor 5.2 m wide (rows 44-56) with walls above and below. At its east end it
    opens onto unknown open space; 80 cells (32 m) west of it, its north wall has a 2-cell notch
    whose inside is unknown (a sliver: what lies there is wall)."""
    belief = np.full((101, 201), UNKNOWN, dtype=np.uint8)
    belief[44:57, 10:130] = FREE
    belief[43, 10:130] = OCCUPIED
    belief[57, 10:130] = OCCUPIED
    belief[43:58, 9] = OCCUPIED  # the west end is closed
    belief[43, 48:50] = UNKNOWN  # the notch: unknown cells in the wall line, behind it the wall's inside
    belief[42, 40:58] = OCCUPIED
    belief[41:43, 47:51] = OCCUPIED
    belief[42, 48:50] = UNKNOWN
    return belief


OPEN_END = (128, 50)  # (col, row) at the corridor's open east end
NOTCH = (49, 45)  # just under the notch, far from the open end


def test_counts_tell_the_open_end_from_the_notch():
    counts = gate_features(corridor_belief(), np.array([OPEN_END, NOTCH]), RANGE_CELLS, wall_margin=2)
    assert counts.shape == (2, len(FEATURES))
    open_unknown, unknown, frontier = counts.T
    assert np.all(open_unknown <= unknown)
    assert open_unknown[0] > 200 and frontier[0] > 5  # the open end looks into wide unknown space
    assert open_unknown[1] == 0 and unknown[1] > 0  # the notch's unknown is all next to walls


def test_the_shipped_gate_calls_the_open_end_big_and_the_notch_a_sliver():
    gate, protocol = load_gate(SHIPPED_GATE)
    assert protocol is not None and protocol["sensor_range"] / protocol["cell_size"] == gate.range_cells
    passes = gate.passes(corridor_belief(), np.array([OPEN_END, NOTCH]), RANGE_CELLS)
    assert passes.tolist() == [True, False]


def test_probability_and_threshold():
    gate = SliverGate.logistic((1.0, 0.0, 0.0), -np.log1p(9.0), threshold=0.5)
    p = gate.probability(np.array([[0.0, 5, 5], [9.0, 5, 5], [99.0, 5, 5]]))
    assert p[0] < 0.5 and p[1] == pytest.approx(0.5) and p[2] > 0.5
    with pytest.raises(ValueError, match="threshold"):
        SliverGate.logistic((1.0, 0.0, 0.0), 0.0, threshold=1.0)
    with pytest.raises(ValueError, match="expected 3 rows"):
        SliverGate.logistic((1.0, 0.0), 0.0)
    with pytest.raises(ValueError, match="finite"):
        SliverGate.logistic((float("nan"), 0.0, 0.0), 0.0)
    with pytest.raises(ValueError, match="to one output"):
        SliverGate(((((1.0, 1.0),) * 3, (0.0, 0.0)),))  # two outputs


def test_a_hidden_layer_computes_relu_then_sigmoid():
    # hidden unit 0 = relu(log1p(open) - log1p(9)), unit 1 = relu(-log1p(open)); output = 2 * unit 0 - unit 1
    gate = SliverGate(((((1.0, -1.0), (0.0, 0.0), (0.0, 0.0)), (-np.log1p(9.0), 0.0)), (((2.0,), (-1.0,)), (0.0,))))
    p = gate.probability(np.array([[0.0, 5, 5], [99.0, 5, 5]]))
    assert p[0] == pytest.approx(0.5)  # both units are 0 at no open unknown
    assert p[1] == pytest.approx(1 / (1 + np.exp(-2 * (np.log1p(99.0) - np.log1p(9.0)))))


def test_fit_learns_the_share_of_open_unknown():
    rng = np.random.default_rng(0)
    unknown = rng.integers(20, 2000, 4000).astype(float)
    share = rng.uniform(0, 1, 4000)
    counts = np.column_stack([unknown * share, unknown, rng.integers(0, 60, 4000)])
    gains = np.where(share > 0.5, 200, 10) + rng.integers(0, 5, 4000)
    labels = gains >= 50
    gate = fit_sliver_gate(counts, gains, min_gain=50, wall_margin=2, range_cells=50.0)
    ((coef, _),) = gate.layers
    assert coef[0][0] > 0 > coef[1][0]  # open unknown counts for big, all unknown against
    for fitted in (gate, fit_sliver_gate(counts, gains, min_gain=50, wall_margin=2, range_cells=50.0, hidden=(8,))):
        assert ((fitted.probability(counts) >= 0.5) == labels).mean() > 0.9
        assert roc_auc(fitted.probability(counts), labels) > 0.95
    assert len(fitted.layers) == 2 and len(fitted.layers[0][1]) == 8
    with pytest.raises(ValueError, match="every one"):
        fit_sliver_gate(counts, np.zeros(4000), min_gain=50, wall_margin=2, range_cells=50.0)


def test_a_fit_on_drawn_samples_is_the_fit_on_that_subset():
    """`max_samples` draws that many samples by the seed and fits on them; fewer samples are all used."""
    rng = np.random.default_rng(1)
    unknown = rng.integers(20, 2000, 3000).astype(float)
    share = rng.uniform(0, 1, 3000)
    counts = np.column_stack([unknown * share, unknown, rng.integers(0, 60, 3000)])
    gains = np.where(share > 0.5, 200, 10)
    settings = dict(min_gain=50, wall_margin=2, range_cells=50.0, seed=3)
    drawn = np.sort(np.random.default_rng(3).choice(3000, 500, replace=False))
    assert fit_sliver_gate(counts, gains, max_samples=500, **settings) == fit_sliver_gate(
        counts[drawn], gains[drawn], **settings
    )
    assert fit_sliver_gate(counts, gains, max_samples=500, **settings) != fit_sliver_gate(counts, gains, **settings)
    assert fit_sliver_gate(counts, gains, max_samples=5000, **settings) == fit_sliver_gate(counts, gains, **settings)


def test_file_round_trip_and_clear_errors(tmp_path):
    gate = SliverGate(
        ((((1.0, -2.0),) * 3, (0.5, 0.0)), (((1.5,), (-1.0,)), (-0.25,))),
        threshold=0.6,
        wall_margin=3,
        min_gain=40,
        range_cells=25.0,
    )
    path = save_gate(gate, tmp_path / "g" / "gate.json", {"cell_size": 0.4}, samples=12)
    loaded, protocol = load_gate(path)
    assert loaded == gate and protocol == {"cell_size": 0.4}
    old = tmp_path / "logistic.json"  # a gate file of the one-layer format that came first
    old.write_text(json.dumps({"features": list(FEATURES), "gate": {"coef": [20.0, -20.0, 3.0], "intercept": -7.0}}))
    assert load_gate(old)[0] == SliverGate.logistic((20.0, -20.0, 3.0), -7.0)
    assert json.loads(path.read_text())["samples"] == 12
    body = json.loads(path.read_text())
    body["gate"]["typo"] = 1
    path.write_text(json.dumps(body))
    with pytest.raises(ValueError, match=r"gate\.json: not a sliver gate file .*typo"):
        load_gate(path)
    (tmp_path / "bad.json").write_text("{")
    with pytest.raises(ValueError, match="bad.json: not a sliver gate file"):
        load_gate(tmp_path / "bad.json")
    with pytest.raises(ValueError, match="does not exist"):
        resolve_gate_path(tmp_path / "missing.json")
    assert resolve_gate_path(path) == path
    assert resolve_gate_path(None) == SHIPPED_GATE  # no fitted gate in models/ under the tests


def test_a_map_at_twice_the_resolution_is_gated_alike():
    gate, _ = load_gate(SHIPPED_GATE)
    fine = np.kron(corridor_belief(), np.ones((2, 2), dtype=np.uint8))  # every cell split in four
    cells = np.array([OPEN_END, NOTCH])
    assert (
        gate.passes(fine, 2 * cells, 2 * RANGE_CELLS).tolist()
        == gate.passes(corridor_belief(), cells, RANGE_CELLS).tolist()
    )
