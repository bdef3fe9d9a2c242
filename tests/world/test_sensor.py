import numpy as np
import pytest
from protocol_reference import reference_scan

from pipeline.world.geometry import sensor_angles
from pipeline.world.sensor import FREE, Belief, scan


def test_720_rays():
    assert len(sensor_angles(0.5)) == 720


@pytest.mark.parametrize("seed", range(6))
def test_scan_matches_reference_loop_cell_for_cell(seed):
    rng = np.random.default_rng(seed)
    rows, cols = rng.integers(30, 90, size=2)
    ground = rng.random((rows, cols)) > rng.uniform(0.05, 0.3)
    range_cells = float(rng.choice([10, 25, 50]))
    for _ in range(4):
        # Anywhere, even on occupied cells or near the edge: the walk rules still apply.
        x0, y0 = int(rng.integers(0, cols)), int(rng.integers(0, rows))
        belief = Belief(ground.shape)
        result = scan(ground, (x0, y0), range_cells)
        for cells in (result.free, result.occupied):  # each cell once, in flat order
            np.testing.assert_array_equal(cells, np.unique(cells))
        belief.apply(result)
        np.testing.assert_array_equal(belief.grid, reference_scan(ground, x0, y0, range_cells))


def test_belief_counts_new_free_cells_once():
    ground = np.ones((40, 40), dtype=bool)
    ground[0, :] = ground[-1, :] = ground[:, 0] = ground[:, -1] = False
    belief = Belief(ground.shape)
    changed = belief.apply(scan(ground, (20, 20), 10))
    assert changed.size > 0
    first = belief.free_count
    assert first == int((belief.grid == FREE).sum())
    assert belief.apply(scan(ground, (20, 20), 10)).size == 0
    assert belief.free_count == first
