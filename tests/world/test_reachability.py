"""Passable cells at a robot's radius and the free area it reaches (scoring)."""

import numpy as np

from pipeline.world.reachability import clearance_cells, passable_mask, reachable_free, reachable_from
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN


def corridor(width: int) -> np.ndarray:
    """A 40 x 40 free square split by a wall (rows 18-21) with a gap `width` cells wide."""
    belief = np.full((40, 40), FREE, np.uint8)
    belief[18:22, :] = OCCUPIED
    belief[18:22, 10 : 10 + width] = FREE
    return belief


def test_a_gap_narrower_than_the_robot_is_not_passable():
    # The centre must be at least the radius from every wall cell's centre: 7 cells pass a radius of 4.
    for width, passes in ((3, False), (6, False), (7, True)):
        belief = corridor(width)
        reach = reachable_from(passable_mask(belief, 4.0), (5, 5))
        assert bool(reach[30, 5]) is passes, width


def test_one_cell_of_radius_keeps_every_known_free_cell():
    belief = corridor(1)
    belief[0, 0] = UNKNOWN
    assert np.array_equal(passable_mask(belief, 1.0), belief == FREE)
    assert clearance_cells(np.full((3, 3), FREE, np.uint8)).min() == np.inf


def test_the_reachable_area_is_the_start_side_when_the_robot_does_not_fit():
    free = corridor(3) == FREE
    narrow = reachable_free(free, (5, 5), 4.0)
    assert not narrow[30:, :].any() and narrow[:10, :].any()
    assert reachable_free(free, (5, 5), 1.0)[30:, :].all()
    wide = reachable_free(corridor(11) == FREE, (5, 5), 4.0)
    # The body reaches the cells beside the walls that its centre never stands on.
    assert wide[17, 0] and wide[0, 0]


def test_an_unseen_slot_one_cell_wide_is_no_region_left_but_a_room_is():
    from pipeline.world.reachability import largest_unseen_region

    free = np.ones((30, 30), bool)
    belief = np.full(free.shape, FREE, np.uint8)
    belief[2:28, 10] = UNKNOWN  # a slot between two walls, one cell wide
    assert largest_unseen_region(free, belief, 1.0) == 0
    belief[15:20, 15:20] = UNKNOWN  # a 5 x 5 room
    assert largest_unseen_region(free, belief, 1.0) == 25
    assert largest_unseen_region(free, belief, 4.0) == 0  # narrower than a robot of 8 cells across
