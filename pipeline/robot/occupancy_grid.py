"""A robot's SLAM map (`nav_msgs/OccupancyGrid`) as the belief a planner reads.

An OccupancyGrid has `info.resolution` (metres per cell), `info.width` x `info.height` cells, the
map-frame position of cell (0, 0)'s corner (`info.origin.position.x`, `.y`) and `data`, row-major
from that corner with rows along +y: -1 unknown, 0..100 the probability (%) that a cell is
occupied. Any object with those fields will do: rclpy's and rosbags' messages as they are, or
`GridMessage` here.

A cell of the protocol's size (`cell_size`, coarser than SLAM's 0.05 m as a rule) is judged
conservatively from the message cells whose centres fall in it: occupied where any of them is,
free only where all of them are, unknown otherwise. A message coarser than the protocol is first
split into cells no larger than the protocol's.

That rule alone would close doors: a 0.6 m door of a 0.05 m map is 3 cells of 0.2 m, and the two at
its frames hold wall. So a robot radius (`robot_radius_m`) keeps the way open: a cell judged
occupied is free after all when one of its message cells is one the robot's centre may stand on
(known free, no occupied message cell nearer than the radius) and none of them is unknown. Every
door the robot fits through, at the map's own resolution, stays passable on the coarse grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, cast

import numpy as np

from pipeline.world.reachability import passable_mask
from pipeline.world.resample import ROS_FREE_VALUE, ROS_OCCUPIED_VALUE, ROS_UNKNOWN_VALUE, write_map_server
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN

FREE_MAX = 19  # a probability (%) at or below this is free: ROS map_server's free_thresh, 0.196
OCCUPIED_MIN = 65  # at or above this, occupied: map_server's occupied_thresh, 0.65


class BadMessage(ValueError):
    """A map message the session cannot use (its reason in one line); the session logs and skips it."""


@dataclass(frozen=True)
class Grid:
    """A message's cells checked and read: `values[row, col]` (-1..100), rows along +y from `origin`."""

    values: np.ndarray
    resolution: float
    origin: tuple[float, float]

    @property
    def extent(self) -> tuple[float, float, float, float]:
        """(x0, y0, x1, y1) of the grid in the map frame, metres."""
        rows, cols = self.values.shape
        x0, y0 = self.origin
        return x0, y0, x0 + cols * self.resolution, y0 + rows * self.resolution


def read_grid(msg: Any) -> Grid:
    """The message's grid, or BadMessage saying what is wrong with it."""
    try:
        info = msg.info
        resolution = float(info.resolution)
        width, height = int(info.width), int(info.height)
        x0, y0 = float(info.origin.position.x), float(info.origin.position.y)
        data = msg.data
    except (AttributeError, TypeError, ValueError) as error:
        raise BadMessage(f"not an OccupancyGrid ({type(error).__name__}: {error})") from None
    if not (math.isfinite(resolution) and resolution > 0):
        raise BadMessage(f"resolution must be a positive number of metres, got {resolution!r}")
    if not (math.isfinite(x0) and math.isfinite(y0)):
        raise BadMessage(f"origin must be finite, got ({x0!r}, {y0!r})")
    if width <= 0 or height <= 0:
        raise BadMessage(f"the map is empty ({width} x {height} cells)")
    try:
        values = np.asarray(data, dtype=np.int64).reshape(-1)
    except (TypeError, ValueError, OverflowError) as error:
        raise BadMessage(f"data is not a list of integers ({error})") from None
    if values.size != width * height:
        raise BadMessage(f"data holds {values.size} values for {width} x {height} = {width * height} cells")
    if values.size and (values.min() < -1 or values.max() > 100):
        raise BadMessage(f"data values must lie in -1..100, got {int(values.min())}..{int(values.max())}")
    return Grid(values.reshape(height, width), resolution, (x0, y0))


@dataclass
class Canvas:
    """The belief on a grid of the protocol's cell size that only grows: the session's map.

    Its lattice is anchored at `anchor` (the first pose): the canvas grows by whole lattice steps,
    so a node keeps its place in the map frame when the canvas grows. `grow` says whether it did.
    """

    cell_size: float
    step_cells: int  # lattice spacing in cells (node_resolution / cell_size)
    anchor: tuple[float, float]  # map-frame metres of the start cell's centre
    belief: np.ndarray = field(default_factory=lambda: np.full((1, 1), UNKNOWN, np.uint8))
    start_cell: tuple[int, int] = (0, 0)  # (col, row) of the anchor
    robot_radius_m: float = 0.0  # a cell the robot's centre may stand on in a finer map stays free (module doc)

    @property
    def origin(self) -> tuple[float, float]:
        """Map-frame metres of cell (0, 0)'s corner."""
        return (
            self.anchor[0] - (self.start_cell[0] + 0.5) * self.cell_size,
            self.anchor[1] - (self.start_cell[1] + 0.5) * self.cell_size,
        )

    def to_cell(self, x: float, y: float) -> tuple[int, int]:
        """(col, row) of the canvas cell that holds map-frame point (x, y) (it may lie outside)."""
        ox, oy = self.origin
        return int(math.floor((x - ox) / self.cell_size)), int(math.floor((y - oy) / self.cell_size))

    def to_map(self, world: tuple[float, float]) -> tuple[float, float]:
        """A planner's position (metres from the start cell) in the map frame."""
        return self.anchor[0] + float(world[0]), self.anchor[1] + float(world[1])

    def to_world(self, x: float, y: float) -> tuple[float, float]:
        """A map-frame point as a planner's position (metres from the start cell)."""
        return x - self.anchor[0], y - self.anchor[1]

    def contains(self, extent: tuple[float, float, float, float]) -> bool:
        """Whether map-frame `extent` (x0, y0, x1, y1) lies inside the canvas."""
        rows, cols = self.belief.shape
        c0, r0 = self.to_cell(extent[0], extent[1])
        c1, r1 = self.to_cell(extent[2], extent[3])
        return c0 >= 0 and r0 >= 0 and c1 < cols and r1 < rows

    def cover(self, extent: tuple[float, float, float, float], margin_m: float = 0.0) -> bool:
        """Grow (by whole lattice steps) until `extent` (x0, y0, x1, y1) plus `margin_m` lies inside;
        True when the canvas grew."""
        x0, y0, x1, y1 = extent
        rows, cols = self.belief.shape
        c0, r0 = self.to_cell(x0 - margin_m, y0 - margin_m)
        c1, r1 = self.to_cell(x1 + margin_m, y1 + margin_m)
        step = self.step_cells
        left = _steps(-c0, step)
        bottom = _steps(-r0, step)
        right = _steps(c1 - (cols - 1), step)
        top = _steps(r1 - (rows - 1), step)
        if not (left or bottom or right or top):
            return False
        self.belief = np.pad(self.belief, ((bottom, top), (left, right)), constant_values=UNKNOWN)
        self.start_cell = (self.start_cell[0] + left, self.start_cell[1] + bottom)
        return True

    def paint(self, grid: Grid) -> None:
        """The message's cells, judged at the canvas's cell size, over the belief (cells it does not
        cover keep what they were)."""
        values, resolution = grid.values, grid.resolution
        split = max(1, int(math.ceil(resolution / self.cell_size - 1e-9)))
        if split > 1:  # a coarser map: each of its cells as split x split smaller ones
            values = np.repeat(np.repeat(values, split, axis=0), split, axis=1)
            resolution = resolution / split
        rows, cols = values.shape
        ox, oy = self.origin
        col = np.floor((grid.origin[0] + (np.arange(cols) + 0.5) * resolution - ox) / self.cell_size).astype(np.int64)
        row = np.floor((grid.origin[1] + (np.arange(rows) + 0.5) * resolution - oy) / self.cell_size).astype(np.int64)
        height, width = self.belief.shape
        inside_c, inside_r = (col >= 0) & (col < width), (row >= 0) & (row < height)
        if not inside_c.any() or not inside_r.any():
            return
        fits = self._fits_robot(values, resolution)
        cols_in, rows_in = np.flatnonzero(inside_c), np.flatnonzero(inside_r)  # contiguous: the cells ascend
        window = (slice(rows_in[0], rows_in[-1] + 1), slice(cols_in[0], cols_in[-1] + 1))
        values = values[window]
        col, row = col[window[1]], row[window[0]]
        # The message's cells ascend in runs, one per canvas cell (they are no coarser than it): the
        # counts over each run of rows and columns, summed block by block.
        col_starts = np.flatnonzero(np.diff(col, prepend=col[0] - 1))
        row_starts = np.flatnonzero(np.diff(row, prepend=row[0] - 1))
        widths = np.diff(col_starts, append=len(col))
        heights = np.diff(row_starts, append=len(row))
        total = heights[:, None] * widths[None, :]

        even = (widths == widths[0]).all() and (heights == heights[0]).all()

        def count(mask: np.ndarray) -> np.ndarray:
            if even:  # whole blocks of one size (an aligned finer map): sums of strided slices, fast
                h, w = int(heights[0]), int(widths[0])
                rows_summed = cast(np.ndarray, sum(mask[k::h].astype(np.int32) for k in range(h)))
                return cast(np.ndarray, sum(rows_summed[:, k::w] for k in range(w)))
            per_col = np.add.reduceat(mask.astype(np.int32), col_starts, axis=1)
            return np.add.reduceat(per_col, row_starts, axis=0)

        occupied = count(values >= OCCUPIED_MIN)
        free = count((values >= 0) & (values <= FREE_MAX))
        judged = np.full(total.shape, UNKNOWN, np.uint8)
        judged[free == total] = FREE
        judged[occupied > 0] = OCCUPIED
        if fits is not None:  # doors the conservative rule would close (module doc)
            standing = count(fits[window])
            judged[(standing > 0) & (occupied + free == total)] = FREE
        r0, c0 = int(row[0]), int(col[0])
        self.belief[r0 : r0 + total.shape[0], c0 : c0 + total.shape[1]] = judged

    def _fits_robot(self, values: np.ndarray, resolution: float) -> np.ndarray | None:
        """Per message cell, whether the robot's centre may stand there (known free, no occupied cell
        nearer than its radius); None when the message is no finer than the canvas or there is no radius."""
        if self.robot_radius_m <= 0 or resolution >= self.cell_size - 1e-9:
            return None
        trinary = np.full(values.shape, UNKNOWN, np.uint8)
        trinary[(values >= 0) & (values <= FREE_MAX)] = FREE
        trinary[values >= OCCUPIED_MIN] = OCCUPIED
        return passable_mask(trinary, self.robot_radius_m / resolution)


def write_belief_map(
    belief: np.ndarray, cell_size: float, origin: tuple[float, float], start: tuple[float, float], yaml_path: Path
) -> Path:
    """A belief grid (rows grow with y) as map_saver writes a map (`write_map_server`: free 254,
    occupied 0, unknown 205) with `origin` (the grid's corner) and a `start` key, map frame; the
    YAML's path."""
    image = np.full(belief.shape, ROS_UNKNOWN_VALUE, np.uint8)
    image[belief == FREE], image[belief == OCCUPIED] = ROS_FREE_VALUE, ROS_OCCUPIED_VALUE
    write_map_server(image, float(cell_size), origin, start, yaml_path)
    return Path(yaml_path)


def _steps(cells: int, step: int) -> int:
    """Cells to add on one side to reach `cells` beyond the edge, in whole lattice steps (0 if none)."""
    return 0 if cells <= 0 else int(math.ceil(cells / step)) * step


@dataclass
class GridMessage:
    """An OccupancyGrid's fields, for tests and for callers without ROS message types."""

    data: list[int] | np.ndarray
    width: int
    height: int
    resolution: float
    origin_x: float = 0.0
    origin_y: float = 0.0

    @property
    def info(self) -> Any:
        position = _Namespace(x=self.origin_x, y=self.origin_y, z=0.0)
        return _Namespace(
            resolution=self.resolution, width=self.width, height=self.height, origin=_Namespace(position=position)
        )


class _Namespace:
    def __init__(self, **values: Any) -> None:
        self.__dict__.update(values)
