"""The coverage-curve figure (pipeline/reporting/coverage_figure.py)."""

from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

from pipeline.evaluation.exploration_curves import SpeedModel, step_record
from pipeline.reporting.coverage_figure import coverage_figure


def record(distances, shares):
    return step_record(
        {"step": k, "distance_m": d, "explored_m2": 10 * s, "explored_share": s, "decision_ms": 5.0}
        for k, (d, s) in enumerate(zip(distances, shares))
    )


def test_draws_two_panels_with_a_line_per_planner(tmp_path):
    records = {
        ("a", "m1"): record([0, 4, 8], [0.3, 0.7, 1.0]),
        ("a", "m2"): record([0, 4], [0.5, 1.0]),
        ("b", "m1"): record([0, 8, 16], [0.3, 0.5, 0.99]),
    }
    path = coverage_figure(records, tmp_path / "out/coverage.png", SpeedModel(1.0), title="t")
    image = np.asarray(Image.open(path).convert("RGB"))
    assert image.shape[1] > 1.5 * image.shape[0]  # side by side: distance and time
    assert len(np.unique(image.reshape(-1, 3), axis=0)) > 20  # lines and bands were drawn, not a blank canvas


def test_nothing_to_draw_is_an_error(tmp_path):
    with pytest.raises(ValueError, match="no per-step records"):
        coverage_figure({}, tmp_path / "c.png")
