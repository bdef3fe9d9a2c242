import numpy as np
import pytest

from pipeline.world.geometry import segment_is_known_free, walk_cells, walk_offsets


@pytest.mark.parametrize("dx,dy", [(0, 0), (5, 0), (0, -7), (10, 10), (-20, 7), (3, -11)])
def test_walk_is_four_connected_and_monotone(dx, dy):
    cells = walk_offsets(dx, dy)
    assert tuple(cells[0]) == (0, 0) and tuple(cells[-1]) == (dx, dy)
    assert len(cells) == abs(dx) + abs(dy) + 1
    steps = np.abs(np.diff(cells, axis=0)).sum(axis=1)
    assert (steps == 1).all()


def test_walk_is_not_symmetric_but_motion_accepts_either_direction():
    forward = {tuple(c) for c in walk_cells((0, 0), (5, 3))}
    backward = {tuple(c) for c in walk_cells((5, 3), (0, 0))}
    assert forward != backward
    for cells, expected in ((forward, True), (backward, True), (forward & backward, False)):
        free = np.zeros((4, 6), dtype=bool)
        for x, y in cells:
            free[y, x] = True
        assert segment_is_known_free(free, (0, 0), (5, 3)) is expected


def test_segment_outside_grid_is_not_free():
    free = np.ones((5, 5), dtype=bool)
    assert not segment_is_known_free(free, (0, 0), (7, 0))
