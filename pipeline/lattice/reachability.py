"""The frontier a robot can drive to, and the way there, asked on cells rather than on a lattice.

A lattice graph reaches only the cells its straight edges join. These questions are asked on the
cells themselves (`pipeline.world.reachability`'s passable cells), so that "done" means no
frontier cell is left that the robot could drive to (docs/protocol.md, "The whole building"), and
so that a robot the lattice strands still gets there: a breadth-first path over passable cells,
pulled tight into waypoints whose segments follow the protocol's walk.
"""

from __future__ import annotations

import cv2
import numba
import numpy as np

from pipeline.lattice.frontier import FRONTIER_MIN_UNKNOWN_NEIGHBOURS, frontier_mask
from pipeline.world.geometry import segment_is_known_free
from pipeline.world.sensor import UNKNOWN

Cell = tuple[int, int]  # (col, row)

_CROSS = np.array([[0, 1, 0], [1, 1, 1], [0, 1, 0]], dtype=np.uint8)


def open_frontier(
    belief: np.ndarray, min_unknown_cells: int, min_unknown_neighbours: int = FRONTIER_MIN_UNKNOWN_NEIGHBOURS
) -> np.ndarray:
    """The frontier cells (`frontier_mask`) that a visit clears and that lead somewhere: those with
    an unknown cell among their 4 neighbours (every ray's first step reveals one; a cell that sees
    unknown space only across a wall's corner never does) that belongs to an unknown region of at
    least `min_unknown_cells` cells (8-connected)."""
    unknown = belief == UNKNOWN
    if not unknown.any():
        return np.zeros(belief.shape, dtype=bool)
    _, labels, stats, _ = cv2.connectedComponentsWithStats(unknown.view(np.uint8), connectivity=8)
    large = unknown & (stats[labels, cv2.CC_STAT_AREA] >= min_unknown_cells)
    beside = cv2.dilate(large.view(np.uint8), _CROSS, borderType=cv2.BORDER_CONSTANT, borderValue=0).view(bool)
    return frontier_mask(belief, min_unknown_neighbours) & beside


def path_to_nearest(passable: np.ndarray, targets: np.ndarray, start: Cell) -> list[Cell]:
    """The cells of a shortest 4-connected path through `passable` from `start` to the nearest
    `targets` cell (both ends included); [] when none is reachable."""
    rows, cols = passable.shape
    flat = _bfs_to_target(
        np.ascontiguousarray(passable, dtype=np.bool_),
        np.ascontiguousarray(targets, dtype=np.bool_),
        start[1] * cols + start[0],
    )
    return [(int(f % cols), int(f // cols)) for f in flat]


def waypoints_along(free: np.ndarray, path: list[Cell]) -> list[Cell]:
    """The corners of `path` (cells, the start first) pulled tight: from each corner the farthest
    path cell that the protocol's walk reaches through `free` cells before one it does not. The
    start is left out; the last cell of the path is the last corner."""
    if len(path) < 2:
        return []
    corners: list[Cell] = []
    here = 0
    while here < len(path) - 1:
        reach = here + 1
        while reach + 1 < len(path) and segment_is_known_free(free, path[here], path[reach + 1]):
            reach += 1
        corners.append(path[reach])
        here = reach
    return corners


@numba.njit(cache=True, nogil=True)
def _bfs_to_target(passable, targets, start_flat):  # pragma: no cover - compiled
    rows, cols = passable.shape
    parent = np.full(rows * cols, -2, np.int64)
    queue = np.empty(rows * cols, np.int64)
    head, tail = 0, 1
    queue[0] = start_flat
    parent[start_flat] = -1
    found = -1
    while head < tail:
        cell = queue[head]
        head += 1
        r, c = cell // cols, cell % cols
        if targets[r, c]:
            found = cell
            break
        for k in range(4):
            nr, nc = r, c
            if k == 0:
                nr = r - 1
            elif k == 1:
                nr = r + 1
            elif k == 2:
                nc = c - 1
            else:
                nc = c + 1
            if nr < 0 or nr >= rows or nc < 0 or nc >= cols or not passable[nr, nc]:
                continue
            n = nr * cols + nc
            if parent[n] != -2:
                continue
            parent[n] = cell
            queue[tail] = n
            tail += 1
    if found < 0:
        return np.zeros(0, np.int64)
    length = 0
    cell = found
    while cell >= 0:
        length += 1
        cell = parent[cell]
    path = np.empty(length, np.int64)
    cell = found
    for i in range(length - 1, -1, -1):
        path[i] = cell
        cell = parent[cell]
    return path
