import numpy as np
import pytest

from pipeline.world.geometry import sensor_angles
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN, Belief, scan


def reference_scan(ground_free: np.ndarray, x0: int, y0: int, range_cells: float) -> np.ndarray:
    """docs/protocol.md's sensor written as the plain per-ray, per-cell loop."""
    rows, cols = ground_free.shape
    belief = np.full(ground_free.shape, UNKNOWN, dtype=np.uint8)
    angle, step = 0.0, 0.5 / 180 * np.pi
    while angle < 2 * np.pi:
        x1 = int(np.round(x0 + range_cells * np.cos(angle)))
        y1 = int(np.round(y0 + range_cells * np.sin(angle)))
        dx, dy = abs(x1 - x0), abs(y1 - y0)
        sx, sy = np.sign(x1 - x0), np.sign(y1 - y0)
        err = dx - dy
        x, y = x0, y0
        while True:
            if not (0 <= x < cols and 0 <= y < rows):
                break
            if x == x1 and y == y1:
                break
            if not ground_free[y, x]:
                belief[y, x] = OCCUPIED
                break
            belief[y, x] = FREE
            if err > 0:
                x += sx
                err -= 2 * dy
            else:
                y += sy
                err += 2 * dx
        angle += step
    return belief


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
