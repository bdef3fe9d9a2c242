"""Frontier cells: known-free cells that border unknown space."""

from __future__ import annotations

import cv2
import numpy as np

from pipeline.world.sensor import FREE, UNKNOWN

_NEIGHBOUR_KERNEL = np.ones((3, 3), dtype=np.float32)
_NEIGHBOUR_KERNEL[1, 1] = 0.0


FRONTIER_MIN_UNKNOWN_NEIGHBOURS = 2  # DARE's rule, below


def frontier_mask(belief: np.ndarray, min_unknown_neighbours: int = FRONTIER_MIN_UNKNOWN_NEIGHBOURS) -> np.ndarray:
    """Free cells with at least `min_unknown_neighbours` unknown cells among their 8 neighbours.

    Requiring two (as DARE does) ignores single grazing-ray gaps along walls, which no
    viewpoint can close and which would otherwise lure planners into useless detours.
    Cells beyond the grid count as known, so the map's edge is no frontier.
    """
    unknown = (belief == UNKNOWN).astype(np.float32)
    counts = cv2.filter2D(unknown, -1, _NEIGHBOUR_KERNEL, borderType=cv2.BORDER_CONSTANT)
    return (belief == FREE) & (counts >= min_unknown_neighbours - 0.5)


def update_frontier_window(
    frontier: np.ndarray, belief: np.ndarray, box: tuple[int, int, int, int], min_unknown_neighbours: int = 2
) -> tuple[int, int, int, int]:
    """Recompute `frontier` in place inside `box` = (x0, x1, y0, y1) grown by one cell.

    A cell's frontier status only depends on its 3x3 neighbourhood, so cells one step
    outside the changed box are the only others that can change. Returns the grown box.
    """
    rows, cols = belief.shape
    x0, x1, y0, y1 = box
    gx0, gx1, gy0, gy1 = max(0, x0 - 1), min(cols, x1 + 2), max(0, y0 - 1), min(rows, y1 + 2)
    # Read one more ring so neighbour counts at the window's edge are right.
    rx0, rx1, ry0, ry1 = max(0, gx0 - 1), min(cols, gx1 + 1), max(0, gy0 - 1), min(rows, gy1 + 1)
    window = frontier_mask(belief[ry0:ry1, rx0:rx1], min_unknown_neighbours)
    frontier[gy0:gy1, gx0:gx1] = window[gy0 - ry0 : gy1 - ry0, gx0 - rx0 : gx1 - rx0]
    return gx0, gx1 - 1, gy0, gy1 - 1
