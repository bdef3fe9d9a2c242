"""Procedural office floors in the maze PNG format: a second map family, unlike the mazes.

The mazes are rooms of 5 m blocks separated by solid wall blocks. Real floor plans are not:
their walls are thin, their rooms large and open, and furniture casts shadows. An office
floor here is drawn by recursive division. The floor inside a wall ring is split, across its
longer side, by a wall 0.4-0.8 m thick with a door 5.2-6 m wide (sometimes two). Each part
is split again until it is small, deep enough, or stops by chance. Then each room gets a few
boxes of clutter, kept off its walls so that no door is blocked. Doors are wider than the
4 m lattice, so a lattice robot can always pass them.

The sliver gate is fitted on both families (`stages.fit_gate`): fitted on mazes alone it
left real targets behind in office floors and made routes longer there
(docs/findings.md, "Off the maze generator").
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pipeline.world.maps import MAX_IMAGE_PIXELS
from pipeline.world.mazes import FREE_VALUE, START_VALUE, WALL_VALUE, generate_map_set

START_CELLS = 4  # the start is marked as a 4 x 4-cell square: its 11th cell (row-major) is the start


@dataclass(frozen=True)
class OfficeConfig:
    """What kind of office floors to draw; lengths in metres, ranges inclusive."""

    side_m: float = 100.0
    cell_size: float = 0.4
    wall_m: tuple[float, float] = (0.4, 0.8)  # inner wall thickness
    door_m: tuple[float, float] = (5.2, 6.0)  # door width: wider than the 4 m lattice step
    min_room_m: float = 8.0  # no split leaves a room narrower than this
    split_above_m: float = 20.0  # a part whose longer side exceeds this is split (unless it stops by chance)
    max_depth: int = 6  # splits on the way down to a room
    stop_chance: float = 0.25  # from depth 3 on, the chance a part stays one big room
    second_door_chance: float = 0.3  # the chance a long wall gets a second door
    clutter: tuple[int, int] = (0, 4)  # boxes per room
    clutter_m: tuple[float, float] = (1.2, 2.8)  # box side
    clutter_margin_m: float = 4.8  # boxes keep this far from their room's walls (and so from doors)

    def __post_init__(self) -> None:
        if not self.cell_size > 0 or not self.side_m >= 20:
            raise ValueError(f"OfficeConfig needs cell_size > 0 and side_m >= 20 m, got {self.cell_size}, {self.side_m}")
        for name in ("wall_m", "door_m", "clutter", "clutter_m"):
            low, high = getattr(self, name)
            if not 0 <= low <= high:
                raise ValueError(f"OfficeConfig.{name} must be a range low <= high of non-negative values, got {(low, high)}")
        if self.door_m[0] < 4.8:
            raise ValueError(f"OfficeConfig.door_m must start at 4.8 m or more (a 4 m lattice must pass), got {self.door_m}")
        if (2 * self.cells(self.side_m)) ** 2 > MAX_IMAGE_PIXELS:
            largest = math.isqrt(MAX_IMAGE_PIXELS) // 2 * self.cell_size
            raise ValueError(f"office floors of {self.side_m:g} m make an image of more than the map loader reads; "
                             f"the largest side at {self.cell_size:g} m cells is {largest:.0f} m")
        if not 2 * self.min_room_m <= self.split_above_m:
            raise ValueError("OfficeConfig.split_above_m must be at least twice min_room_m (both halves of a split fit)")

    def cells(self, metres: float) -> int:
        """A length in whole cells (at least one)."""
        return max(1, int(round(metres / self.cell_size)))


def draw_office(config: OfficeConfig, rng: np.random.Generator) -> tuple[np.ndarray, tuple[int, int]]:
    """One office floor as a boolean cell grid (True = free) and its start cell (row, col)."""
    n = config.cells(config.side_m)
    free = np.zeros((n, n), dtype=bool)
    free[2:-2, 2:-2] = True
    rooms: list[tuple[int, int, int, int]] = []
    min_room, split_above = config.cells(config.min_room_m), config.cells(config.split_above_m)

    def cells_in(bounds: tuple[float, float]) -> int:
        low, high = (config.cells(v) for v in bounds)
        return int(rng.integers(low, high + 1))

    def split(top: int, left: int, bottom: int, right: int, depth: int) -> None:
        height, width = bottom - top, right - left
        door = cells_in(config.door_m)
        if (depth >= config.max_depth or max(height, width) <= split_above or min(height, width) < door + 4
                or (depth > 2 and rng.random() < config.stop_chance)):
            rooms.append((top, left, bottom, right))
            return
        wall = cells_in(config.wall_m)
        across_rows = height >= width  # cut the longer side
        low, high = (top, bottom) if across_rows else (left, right)
        cut = int(rng.integers(low + min_room, high - min_room - wall + 1))
        span = (left, right) if across_rows else (top, bottom)
        doors = 1 + int(span[1] - span[0] > 3 * door + 10 and rng.random() < config.second_door_chance)
        if across_rows:
            free[cut : cut + wall, left:right] = False
        else:
            free[top:bottom, cut : cut + wall] = False
        for _ in range(doors):
            start = int(rng.integers(span[0] + 2, span[1] - door - 1))
            if across_rows:
                free[cut : cut + wall, start : start + door] = True
            else:
                free[start : start + door, cut : cut + wall] = True
        if across_rows:
            split(top, left, cut, right, depth + 1)
            split(cut + wall, left, bottom, right, depth + 1)
        else:
            split(top, left, bottom, cut, depth + 1)
            split(top, cut + wall, bottom, right, depth + 1)

    split(2, 2, n - 2, n - 2, 0)
    margin = config.cells(config.clutter_margin_m)
    for top, left, bottom, right in rooms:
        for _ in range(int(rng.integers(config.clutter[0], config.clutter[1] + 1))):
            box_h, box_w = cells_in(config.clutter_m), cells_in(config.clutter_m)
            if bottom - top - box_h <= 2 * margin or right - left - box_w <= 2 * margin:
                continue
            row = int(rng.integers(top + margin, bottom - margin - box_h))
            col = int(rng.integers(left + margin, right - margin - box_w))
            free[row : row + box_h, col : col + box_w] = False
    # Clutter may close a pocket off: keep the largest 4-connected free space only.
    _, labels = cv2.connectedComponents(free.astype(np.uint8), connectivity=4)
    sizes = np.bincount(labels.ravel())
    sizes[0] = 0
    free = labels == int(sizes.argmax())
    return free, _start_cell(free, rooms, rng)


def _start_cell(free: np.ndarray, rooms: list[tuple[int, int, int, int]], rng: np.random.Generator) -> tuple[int, int]:
    """A start in a random room, with free cells all around the START_CELLS square that marks it."""
    clear = cv2.erode(free.astype(np.uint8), np.ones((2 * START_CELLS + 1,) * 2, np.uint8)).astype(bool)
    for index in rng.permutation(len(rooms)):
        top, left, bottom, right = rooms[index]
        rows, cols = np.nonzero(clear[top:bottom, left:right])
        if rows.size:
            pick = int(rng.integers(rows.size))
            return int(top + rows[pick]), int(left + cols[pick])
    raise RuntimeError("office generator bug: no room has space for the start")


def render_free_map(free: np.ndarray, start: tuple[int, int]) -> np.ndarray:
    """The maze PNG image (two pixels per cell) of any free grid, office floor or cave, with the
    start marked so `load_maze_png` finds it.

    The START_CELLS x START_CELLS square of 208 cells is placed so that its 11th cell in
    row-major order, the one the format names as the start, is `start`.
    """
    cells = np.where(free, FREE_VALUE, WALL_VALUE).astype(np.uint8)
    row, col = start[0] - 10 // START_CELLS, start[1] - 10 % START_CELLS
    cells[row : row + START_CELLS, col : col + START_CELLS] = START_VALUE
    return np.kron(cells, np.ones((2, 2), dtype=np.uint8))


def generate_office(config: OfficeConfig, rng: np.random.Generator) -> np.ndarray:
    """Draw one office floor as a maze PNG image (127 wall, 195 free, 208 start square)."""
    return render_free_map(*draw_office(config, rng))


def generate_office_set(config: OfficeConfig, count: int, out_dir: str | Path, seed: int | Sequence[int],
                        prefix: str = "office", progress: bool = True) -> list[Path]:
    """Write `count` office floors as `{prefix}_{i:04d}.png`, floor i drawn from default_rng([*seed, i])."""
    return generate_map_set(lambda rng: generate_office(config, rng), count, out_dir, seed, prefix, progress)
