"""Block-scale geometry: which block a cell is in, shares, true blocks, and drawn worlds."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.prediction.block_maps import (
    block_index,
    block_shares,
    border_ring,
    drawn_world,
    exit_steps,
    grow_within,
    imagined_free,
    true_blocks,
)
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN
from tests.conftest import SMALL_MAZE


def test_block_index_splits_cells_by_their_centres():
    blocks, grid = block_index((25, 30), 0.4, 5.0)  # 10 m x 12 m of 0.4 m cells: 2 x 3 blocks of 5 m
    assert grid == (2, 3) and blocks.shape == (25, 30)
    assert np.array_equal(
        np.bincount(blocks[:, 0] // 3), [12, 13]
    )  # a 12.5-cell block: the split cell's centre is at 5 m
    assert blocks[0, 29] == 2 and blocks[24, 0] == 3 and blocks[24, 29] == 5
    with pytest.raises(ValueError, match="must be positive"):
        block_index((4, 4), 0.4, 0.0)


def test_true_blocks_of_a_maze_png_are_its_picture(small_maze):
    blocks, grid = block_index(small_maze.shape, small_maze.cell_size, 5.0)
    picture = np.array([[char != "#" for char in line] for line in SMALL_MAZE])
    assert grid == picture.shape
    assert np.array_equal(true_blocks(small_maze.free, blocks, grid), picture)


def test_block_shares_count_free_wall_and_unknown_cells():
    blocks, grid = block_index((25, 25), 0.4, 5.0)
    belief = np.full((25, 25), UNKNOWN, dtype=np.uint8)
    belief[:12, :12] = FREE
    belief[12:, 12:] = OCCUPIED
    shares = block_shares(belief, blocks, grid)
    assert shares.shape == (3, 2, 2) and np.allclose(shares.sum(0), 1.0)
    assert np.allclose(shares[:, 0, 0], [1, 0, 0]) and np.allclose(shares[:, 1, 1], [0, 1, 0])
    assert np.allclose(shares[:, 0, 1], [0, 0, 1])
    with pytest.raises(ValueError, match="differ in shape"):
        block_shares(belief[:5], blocks, grid)
    assert border_ring((3, 4)).sum() == 10 and border_ring((3, 4))[1, 1:3].sum() == 0


def test_grow_within_stops_at_the_horizon_and_at_walls():
    allowed = np.zeros((3, 20), dtype=bool)
    allowed[1, :] = True
    allowed[1, 12] = False  # a wall across the corridor
    seed = np.zeros_like(allowed)
    seed[1, 0] = True
    assert np.array_equal(np.nonzero(grow_within(seed, allowed, 5)[1])[0], np.arange(6))
    assert np.array_equal(np.nonzero(grow_within(seed, allowed, 100)[1])[0], np.arange(12))


def test_drawn_world_keeps_the_known_and_adds_drawn_blocks_near_it():
    blocks, grid = block_index((25, 50), 0.4, 5.0)  # 2 x 4 blocks
    belief = np.full((25, 50), UNKNOWN, dtype=np.uint8)
    belief[:12, :12] = FREE  # block (0, 0) known free
    belief[:12, 12:14] = OCCUPIED  # a known wall on its right edge
    drawn = np.zeros(grid, dtype=bool)
    drawn[0, 1:] = drawn[1, 0] = True  # every block of row 0 drawn free, and the one below the known block
    world = drawn_world(belief, blocks, drawn, horizon_cells=15)
    assert world[:12, :12].all() and not world[:12, 12:14].any()  # known free kept, known walls stay walls
    assert world[13:25, 0:12].all()  # the drawn block below, all within 15 cells of the known ones
    assert not world[:12, 14:].any()  # behind the known wall: unreachable, so cut
    assert not drawn_world(belief, blocks, np.zeros(grid, dtype=bool), 15)[12:].any()


def test_exit_steps_count_the_way_to_where_the_cut_hides_imagined_free_space():
    imagined = np.zeros((3, 20), dtype=bool)
    imagined[1, :] = True  # a corridor, free all along in the drawn map
    world = imagined.copy()
    world[1, 15:] = False  # cut at the horizon: the corridor goes on past cell 14
    steps = exit_steps(world, imagined)
    assert steps[1, 14] == 0 and steps[1, 0] == 14  # cell 14 is beside the cut
    assert np.isinf(steps[0, 0]) and np.isinf(steps[1, 15])  # walls and cut cells: no way out through the world
    assert np.isinf(exit_steps(imagined, imagined)).all()  # nothing cut: no exit anywhere


def test_imagined_free_is_the_drawn_world_before_its_cut():
    blocks, grid = block_index((25, 50), 0.4, 5.0)
    belief = np.full((25, 50), UNKNOWN, dtype=np.uint8)
    belief[:12, :12] = FREE
    drawn = np.zeros(grid, dtype=bool)
    drawn[0, 3] = True  # a drawn block out of reach of the known one
    imagined = imagined_free(belief, blocks, drawn)
    assert imagined[:12, :12].all() and imagined[:12, 38:].all() and not imagined[:12, 13:37].any()
    assert not drawn_world(belief, blocks, drawn, 100)[:, 38:].any()
