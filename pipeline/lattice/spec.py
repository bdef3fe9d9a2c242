"""Where the lattice and the regions sit on a grid (LatticeSpec): pure geometry, no belief."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pipeline.lattice.frontier import FRONTIER_MIN_UNKNOWN_NEIGHBOURS


@dataclass(frozen=True)
class LatticeSpec:
    """Where the lattice and the regions sit on a grid; pure geometry, no belief."""

    shape: tuple[int, int]  # grid (rows, cols)
    start_cell: tuple[int, int]  # (col, row)
    cell_size: float
    node_resolution: float
    utility_range: float
    region_size: float
    frontier_min_unknown_neighbours: int = FRONTIER_MIN_UNKNOWN_NEIGHBOURS
    # The robot's radius in cells when edges may pass through door nodes (`pipeline.lattice.doors`),
    # None for DARE's lattice of straight edges only.
    door_radius_cells: float | None = None

    @classmethod
    def for_map(cls, ground_truth, protocol) -> "LatticeSpec":
        """The lattice every planner uses on a map under a protocol (door nodes where it says)."""
        return cls(
            shape=ground_truth.shape,
            start_cell=ground_truth.start_cell,
            cell_size=protocol.cell_size,
            node_resolution=protocol.node_resolution,
            utility_range=protocol.utility_range,
            region_size=protocol.region_size,
            door_radius_cells=protocol.robot_radius_cells if protocol.uses_door_graph else None,
        )

    @property
    def node_step_cells(self) -> float:
        return self.node_resolution / self.cell_size

    def lattice_range(self, axis: int) -> np.ndarray:
        """Lattice indices along x (axis 0) or y (axis 1) whose cells lie in the grid."""
        start = self.start_cell[axis]
        size = self.shape[1 - axis]
        step = self.node_step_cells
        low = int(np.ceil((-start - 0.5) / step))
        high = int(np.floor((size - 1 - start + 0.5) / step))
        idx = np.arange(low - 1, high + 2)
        cells = start + np.round(idx * step).astype(np.int64)
        return idx[(cells >= 0) & (cells < size)]

    def node_indices(self) -> np.ndarray:
        """(i, j) lattice index of every node, ids row-major over the lattice (rows along y)."""
        grid_j, grid_i = np.meshgrid(self.lattice_range(1), self.lattice_range(0), indexing="ij")
        return np.stack([grid_i.ravel(), grid_j.ravel()], axis=1)

    def world_to_cell(self, xy: np.ndarray) -> np.ndarray:
        """World metres (x, y) to grid cells (col, row), origin at the start cell."""
        xy = np.asarray(xy, dtype=np.float64)
        return np.round(xy / self.cell_size).astype(np.int64) + np.asarray(self.start_cell)

    def cell_to_world(self, cells: np.ndarray) -> np.ndarray:
        return (np.asarray(cells, dtype=np.float64) - np.asarray(self.start_cell)) * self.cell_size
