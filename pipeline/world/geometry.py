"""Pure grid geometry: the protocol's 4-connected walk, and walk tables for vectorised use.

Every line-of-sight question in the project (sensor rays, the motion rule, graph edges,
frontier visibility) is answered with the same walk, so the simulator and the planners
can never disagree about which cells a segment crosses.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np


def walk_offsets(dx: int, dy: int) -> np.ndarray:
    """Cells visited by the protocol's 4-connected walk from (0, 0) to (dx, dy), both ends.

    err = |dx| - |dy|; if err > 0 step x and err -= 2|dy|, else step y and err += 2|dx|.
    The walk only depends on the offset, so callers translate it to any start cell.
    Returns an int array of shape (|dx| + |dy| + 1, 2) with (x, y) columns.
    """
    return _walk_offsets_cached(int(dx), int(dy))


@lru_cache(maxsize=65536)
def _walk_offsets_cached(dx: int, dy: int) -> np.ndarray:
    adx, ady = abs(dx), abs(dy)
    sx = 1 if dx > 0 else -1
    sy = 1 if dy > 0 else -1
    n = adx + ady
    out = np.zeros((n + 1, 2), dtype=np.int64)
    x = y = 0
    err = adx - ady
    for i in range(1, n + 1):
        if err > 0:
            x += sx
            err -= 2 * ady
        else:
            y += sy
            err += 2 * adx
        out[i, 0] = x
        out[i, 1] = y
    out.setflags(write=False)
    return out


def walk_cells(start: tuple[int, int], end: tuple[int, int]) -> np.ndarray:
    """Cells (x, y) of the walk from `start` to `end`, both included."""
    return walk_offsets(end[0] - start[0], end[1] - start[1]) + np.asarray(start, dtype=np.int64)


def segment_is_known_free(free: np.ndarray, start: tuple[int, int], end: tuple[int, int]) -> bool:
    """Motion rule: the walk in either direction visits only cells where `free` is True.

    `free[row, col]` is the belief's known-free mask; cells outside the grid are not free.
    """
    for a, b in ((start, end), (end, start)):
        cells = walk_cells(a, b)
        xs, ys = cells[:, 0], cells[:, 1]
        inside = (xs >= 0) & (xs < free.shape[1]) & (ys >= 0) & (ys < free.shape[0])
        if inside.all() and free[ys, xs].all():
            return True
    return False


def sensor_angles(angle_step_deg: float = 0.5) -> np.ndarray:
    """Ray angles exactly as DARE accumulates them: start at 0, add the step while below 2 pi."""
    step = angle_step_deg / 180.0 * np.pi
    angles = []
    angle = 0.0
    while angle < 2 * np.pi:
        angles.append(angle)
        angle += step
    return np.array(angles)


class RayTable:
    """Precomputed walks of a ray fan, padded into one array for vectorised casting.

    `offsets[r, i]` is the i-th cell (x, y) of ray r relative to the origin, the end cell
    excluded (the sensor never reveals it); `valid[r, i]` is False on padding.
    """

    def __init__(self, end_offsets: np.ndarray):
        walks = [walk_offsets(int(ex), int(ey))[:-1] for ex, ey in end_offsets]
        length = max(1, max(len(w) for w in walks))
        self.end_offsets = np.asarray(end_offsets, dtype=np.int64)
        self.offsets = np.zeros((len(walks), length, 2), dtype=np.int64)
        self.valid = np.zeros((len(walks), length), dtype=bool)
        for r, w in enumerate(walks):
            self.offsets[r, : len(w)] = w
            self.valid[r, : len(w)] = True
        # Unique cells of the fan, so that counting visible cells does not count overlaps.
        flat = self.offsets[self.valid]
        self.unique_offsets, inverse = np.unique(flat, axis=0, return_inverse=True)
        self.unique_index = np.full(self.valid.shape, -1, dtype=np.int64)
        self.unique_index[self.valid] = inverse.reshape(-1)


def ray_end_offsets(x0: int, y0: int, range_cells: float, angles: np.ndarray) -> np.ndarray:
    """End cells of each ray relative to the origin, rounded half to even as numpy does."""
    ex = np.round(x0 + range_cells * np.cos(angles)) - x0
    ey = np.round(y0 + range_cells * np.sin(angles)) - y0
    return np.stack([ex, ey], axis=1).astype(np.int64)


@lru_cache(maxsize=64)
def _ray_table_for(end_offsets_bytes: bytes, count: int) -> RayTable:
    return RayTable(np.frombuffer(end_offsets_bytes, dtype=np.int64).reshape(count, 2))


def ray_table(x0: int, y0: int, range_cells: float, angles: np.ndarray) -> RayTable:
    """The ray fan cast from (x0, y0); cached, since it is the same at almost every origin."""
    ends = np.ascontiguousarray(ray_end_offsets(x0, y0, range_cells, angles))
    return _ray_table_for(ends.tobytes(), len(ends))
