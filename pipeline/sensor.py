"""DARE's 2D lidar (PROTOCOL.md "Sensor"), vectorised over rays and ray cells.

All 720 rays are walked at once on a padded table of precomputed walks; the first
stopping cell of each ray is found with one argmax. A plain per-cell loop lives in the
tests as the reference this must match cell for cell.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.geometry import ray_table, sensor_angles

FREE = np.uint8(255)
OCCUPIED = np.uint8(0)
UNKNOWN = np.uint8(128)

DEFAULT_ANGLES = sensor_angles(0.5)


@dataclass(frozen=True)
class ScanResult:
    """Cells revealed by one scan, as flat indices into the grid (row * cols + col)."""

    free: np.ndarray
    occupied: np.ndarray


def scan(
    ground_free: np.ndarray,
    cell: tuple[int, int],
    range_cells: float,
    angles: np.ndarray = DEFAULT_ANGLES,
) -> ScanResult:
    """Cells the lidar at `cell` (col, row) reveals on the ground truth `ground_free[row, col]`.

    Per ray: walk from the robot's cell; stop outside the grid; stop before the end cell;
    reveal an occupied cell and stop; reveal free cells and go on.
    """
    rows, cols = ground_free.shape
    x0, y0 = int(cell[0]), int(cell[1])
    table = ray_table(x0, y0, range_cells, angles)
    xs = table.offsets[..., 0] + x0
    ys = table.offsets[..., 1] + y0
    inside = table.valid & (xs >= 0) & (xs < cols) & (ys >= 0) & (ys < rows)
    flat = np.where(inside, ys * cols + xs, 0)
    is_free = inside & ground_free.reshape(-1)[flat]
    # First cell per ray that is not a free in-grid ray cell: the ray stops there.
    stop = np.where((~is_free).any(axis=1), np.argmax(~is_free, axis=1), is_free.shape[1])
    steps = np.arange(is_free.shape[1])
    revealed_free = steps[None, :] < stop[:, None]
    ray_ids = np.nonzero(stop < is_free.shape[1])[0]
    stop_cells = stop[ray_ids]
    hit = inside[ray_ids, stop_cells]  # in the grid and not padding: occupied, so revealed
    occupied = flat[ray_ids[hit], stop_cells[hit]]
    return ScanResult(free=np.unique(flat[revealed_free]), occupied=np.unique(occupied))


class Belief:
    """The robot's occupancy belief: uint8 grid of FREE / OCCUPIED / UNKNOWN (255 / 0 / 128)."""

    def __init__(self, shape: tuple[int, int]):
        self.grid = np.full(shape, UNKNOWN, dtype=np.uint8)
        self.free_count = 0

    @property
    def free_mask(self) -> np.ndarray:
        return self.grid == FREE

    def apply(self, result: ScanResult) -> np.ndarray:
        """Write a scan into the belief; returns the flat indices of cells that changed."""
        flat = self.grid.reshape(-1)
        new_free = result.free[flat[result.free] != FREE]
        new_occupied = result.occupied[flat[result.occupied] != OCCUPIED]
        flat[new_free] = FREE
        flat[new_occupied] = OCCUPIED
        self.free_count += int(new_free.size)
        return np.concatenate([new_free, new_occupied])
