"""Where a robot of some radius fits on a grid: passable cells and the cells it can reach.

A cell is *passable* for a robot of radius r when it is known free (free, in a ground truth) and
no occupied cell's centre lies closer than r to its centre. Clearance counts occupied cells only:
unknown space is where the robot is going, and a frontier cell always borders it. Connectivity is
4-neighbour, as the protocol's walk is: two free cells that touch only at a corner let no walk
through. The planners ask it of their belief; the benchmark asks it of the ground truth, for the
share of the area a robot can reach that it saw (scoring only).
"""

from __future__ import annotations

import cv2
import numpy as np

from pipeline.world.sensor import FREE, OCCUPIED

Cell = tuple[int, int]  # (col, row)

# Unseen pockets smaller than this (m^2) are no reason to go on: the slivers a lidar leaves along
# walls it sees at a grazing angle, each needing a visit of its own to close. The planners' done
# rule ignores them (`pipeline.lattice.reachability.open_frontier`), and so does an early stop.
LEFTOVER_M2 = 1.0


def clearance_cells(belief: np.ndarray) -> np.ndarray:
    """Per cell, the distance (in cells, centre to centre) to the nearest occupied cell; the grid's
    edge counts as no obstacle."""
    not_occupied = (belief != OCCUPIED).astype(np.uint8)
    if not_occupied.all():
        return np.full(belief.shape, np.inf, dtype=np.float32)
    return cv2.distanceTransform(not_occupied, cv2.DIST_L2, cv2.DIST_MASK_PRECISE)


def passable_mask(belief: np.ndarray, radius_cells: float) -> np.ndarray:
    """Known-free cells whose centre is at least `radius_cells` from every occupied cell's centre.

    A radius of one cell or less keeps every known-free cell: the nearest occupied centre of a free
    cell is at least a cell away.
    """
    free = belief == FREE
    if radius_cells <= 1.0:
        return free
    return free & (clearance_cells(belief) >= radius_cells - 1e-6)


def reachable_from(passable: np.ndarray, start: Cell) -> np.ndarray:
    """The cells of `passable` 4-connected to `start` (the start's own cell counts as passable)."""
    mask = passable.copy()
    col, row = start
    mask[row, col] = True
    _, labels = cv2.connectedComponents(mask.view(np.uint8), connectivity=4)
    return labels == labels[row, col]


def reachable_free(free: np.ndarray, start: Cell, radius_cells: float) -> np.ndarray:
    """The ground truth's free cells a robot of `radius_cells` reaches from `start`: the passable cells
    joined to the start, and every free cell its body covers from one of them (within the radius)."""
    belief = np.where(free, FREE, OCCUPIED).astype(np.uint8)
    centres = reachable_from(passable_mask(belief, radius_cells), start)
    if radius_cells <= 1.0:
        return centres & free
    reach = cv2.distanceTransform((~centres).view(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    return free & (reach <= radius_cells + 1e-6)


def largest_unseen_region(reachable: np.ndarray, belief: np.ndarray, radius_cells: float) -> int:
    """Cells of the largest 8-connected region of `reachable` cells that `belief` does not hold as free
    and that the robot's body fits into (a square as wide as its diameter, two cells at least): a
    slot one cell wide between two walls, or a sliver along one, is no room left unseen."""
    unseen = (reachable & (belief != FREE)).view(np.uint8)
    if not unseen.any():
        return 0
    width = max(2, int(np.ceil(2 * radius_cells - 1e-6)))
    unseen = cv2.morphologyEx(unseen, cv2.MORPH_OPEN, np.ones((width, width), np.uint8))
    if not unseen.any():
        return 0
    _, _, stats, _ = cv2.connectedComponentsWithStats(unseen, connectivity=8)
    return int(stats[1:, cv2.CC_STAT_AREA].max())
