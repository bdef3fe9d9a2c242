"""The map at the scale of maze blocks: what the block model reads and what its samples draw.

The mazes are built from square blocks (`MazeConfig.block_m`, 5 m): a block is wholly free
or wholly wall. Predicting the unseen map block by block is a 20 x 20 problem on a 100 m
maze instead of a 250 x 250 one, and a drawn block map is a plausible maze at once. Blocks
are aligned with the grid's first cell, as the maze PNGs are; on other maps the block size
is only a prior's scale. Pure functions, no state.
"""

from __future__ import annotations

from typing import cast

import cv2
import numpy as np

from pipeline.world.sensor import FREE, UNKNOWN

_CROSS = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))


def block_index(shape: tuple[int, int], cell_size: float, block_m: float) -> tuple[np.ndarray, tuple[int, int]]:
    """(the flat block of every cell, the block grid's (rows, cols)). A cell belongs to the
    block holding its centre, so a 12.5-cell block is split the way the maze image is."""
    if cell_size <= 0 or block_m <= 0:
        raise ValueError(f"cell_size and block_m must be positive, got {cell_size} and {block_m}")
    rows, cols = shape
    row_block = ((np.arange(rows) + 0.5) * cell_size // block_m).astype(np.int64)
    col_block = ((np.arange(cols) + 0.5) * cell_size // block_m).astype(np.int64)
    grid = (int(row_block[-1]) + 1, int(col_block[-1]) + 1)
    return row_block[:, None] * grid[1] + col_block[None, :], grid


def block_shares(belief: np.ndarray, blocks: np.ndarray, grid: tuple[int, int]) -> np.ndarray:
    """(3, rows, cols) float32: the share of each block's cells known free, known wall and unknown."""
    if belief.shape != blocks.shape:
        raise ValueError(f"belief {belief.shape} and block index {blocks.shape} differ in shape")
    count = grid[0] * grid[1]
    flat = blocks.ravel()
    cells = np.bincount(flat, minlength=count).astype(np.float64)
    free = np.bincount(flat, weights=(belief == FREE).ravel(), minlength=count) / cells
    unknown = np.bincount(flat, weights=(belief == UNKNOWN).ravel(), minlength=count) / cells
    return np.stack([free, 1.0 - free - unknown, unknown]).reshape(3, *grid).astype(np.float32)


def true_blocks(free: np.ndarray, blocks: np.ndarray, grid: tuple[int, int]) -> np.ndarray:
    """(rows, cols) bool: blocks whose cells are mostly free in the ground truth."""
    count = grid[0] * grid[1]
    share = np.bincount(blocks.ravel(), weights=free.ravel(), minlength=count) / np.bincount(
        blocks.ravel(), minlength=count
    )
    return (share > 0.5).reshape(grid)


def border_ring(grid: tuple[int, int]) -> np.ndarray:
    """(rows, cols) float32, 1 on the outermost blocks: where a maze's wall ring lies."""
    ring = np.zeros(grid, dtype=np.float32)
    ring[0] = ring[-1] = 1.0
    ring[:, 0] = ring[:, -1] = 1.0
    return ring


def grow_within(seed: np.ndarray, allowed: np.ndarray, steps: int) -> np.ndarray:
    """The cells of `allowed` within `steps` 4-connected moves of `seed` through `allowed`,
    plus `seed`: a drawn map cut to what a rollout could reach in that many cells."""
    region = (seed & allowed).astype(np.uint8)
    mask = allowed.astype(np.uint8)
    for _ in range(max(0, int(steps))):
        grown = cast(np.ndarray, cv2.dilate(region, _CROSS)) & mask
        if np.array_equal(grown, region):
            break
        region = grown
    return region.astype(bool) | seed


def imagined_free(belief: np.ndarray, blocks: np.ndarray, drawn_blocks: np.ndarray) -> np.ndarray:
    """The known free cells and the unknown cells of drawn free blocks, uncut."""
    return (belief == FREE) | ((belief == UNKNOWN) & drawn_blocks.ravel()[blocks])


def drawn_world(belief: np.ndarray, blocks: np.ndarray, drawn_blocks: np.ndarray, horizon_cells: int) -> np.ndarray:
    """A free grid to roll out on: the known free cells, and the unknown cells of drawn free
    blocks within `horizon_cells` of them; everything else (known walls too) is wall."""
    return grow_within(belief == FREE, imagined_free(belief, blocks, drawn_blocks), horizon_cells)


def exit_steps(world: np.ndarray, imagined: np.ndarray) -> np.ndarray:
    """4-connected steps through `world` (a drawn map cut at the horizon) from every cell to the
    nearest cell beside the cut, where `imagined` free space goes on past the horizon; inf where
    none is reachable. A rollout that ends far from the cut leaves the robot far from what is
    still unexplored beyond it, a cost the cut map alone does not show."""
    world_u8 = world.astype(np.uint8)
    beyond = (imagined & ~world).astype(np.uint8)
    reached = cast(np.ndarray, cv2.dilate(beyond, _CROSS)) & world_u8
    steps = np.full(world.shape, np.inf, dtype=np.float32)
    count = 0
    while reached.any():
        steps[reached.astype(bool) & np.isinf(steps)] = count
        grown = cast(np.ndarray, cv2.dilate(reached, _CROSS)) & world_u8
        if np.array_equal(grown, reached):
            break
        reached, count = grown, count + 1
    return steps
