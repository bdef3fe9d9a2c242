"""docs/protocol.md written plainly, for tests that check the simulator against an independent
reading of the protocol: the lidar as a per-ray, per-cell loop, and the explored area after each
waypoint of a trajectory."""

from __future__ import annotations

import numpy as np

from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN


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


def reference_explored_cells(
    ground_free: np.ndarray, start_cell: tuple[int, int], trajectory, cell_size: float, range_cells: float
) -> list[int]:
    """Known free cells after sensing at each row of a trajectory (metres from the start, first row 0,0)."""
    known = np.full(ground_free.shape, UNKNOWN, dtype=np.uint8)
    counts = []
    for x, y in trajectory:
        col = start_cell[0] + int(round(x / cell_size))
        row = start_cell[1] + int(round(y / cell_size))
        seen = reference_scan(ground_free, col, row, range_cells)
        known[(seen != UNKNOWN) & (known == UNKNOWN)] = seen[(seen != UNKNOWN) & (known == UNKNOWN)]
        counts.append(int((known == FREE).sum()))
    return counts
