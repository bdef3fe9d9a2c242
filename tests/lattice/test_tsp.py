"""Tests of the decision-time TSP paths (pipeline/tsp.py)."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from pipeline.lattice.tsp import path_length, tsp_path


def _random_metric(n: int, rng: np.random.Generator) -> np.ndarray:
    points = rng.random((n, 2)) * 100.0
    return np.hypot(*(points[:, None, :] - points[None, :, :]).transpose(2, 0, 1))


@pytest.mark.parametrize("end", [None, "fixed"])
def test_tsp_path_is_optimal_on_small_instances(end):
    rng = np.random.default_rng(11)
    for _ in range(12):
        n = int(rng.integers(3, 8))
        d = _random_metric(n, rng)
        last = None if end is None else int(rng.integers(1, n))
        order = tsp_path(d, last)
        assert order[0] == 0 and sorted(order) == list(range(n))
        if last is not None:
            assert order[-1] == last
        best = min(
            path_length(d, [0, *perm])
            for perm in itertools.permutations(range(1, n))
            if last is None or perm[-1] == last
        )
        assert path_length(d, order) == pytest.approx(best)


def test_tsp_path_heuristic_keeps_the_ends_and_beats_a_naive_order():
    rng = np.random.default_rng(2)
    d = _random_metric(35, rng)
    for last in (None, 17):
        order = tsp_path(d, last, exact_max=8)
        assert order[0] == 0 and sorted(order) == list(range(35))
        if last is not None:
            assert order[-1] == last
        naive = [0, *[k for k in range(1, 35) if k != last], *([last] if last is not None else [])]
        assert path_length(d, order) < 0.6 * path_length(d, naive)
        assert tsp_path(d, last, exact_max=8) == order  # deterministic
