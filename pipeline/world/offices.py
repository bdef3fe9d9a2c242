"""Procedural office floors in the maze PNG format: a second map family, unlike the mazes.

The mazes are rooms of 5 m blocks separated by solid wall blocks. Real floor plans are not:
their walls are thin, their rooms large and open, and furniture casts shadows. An office
floor here is drawn by recursive division. The floor inside a wall ring is split, across its
longer side, by a wall 0.4-0.8 m thick with a door 5.2-6 m wide (sometimes two). Each part
is split again until it is small, deep enough, or stops by chance. Then each room gets a few
boxes of clutter, kept off its walls so that no door is blocked. Doors are wider than the
4 m lattice, so a lattice robot can always pass them.

`OfficeConfig.real_robot` draws the same family at building sizes, for the paper's real-robot
scale (0.2 m cells, a 1 m lattice): walls 0.1-0.3 m, rooms from 3 m, doors from 0.8 m. A door
narrower than the lattice step passes a lattice robot only where a lattice line crosses it, so
such doors are placed over a line of the lattice the floor's start cell fixes (`lattice_m`).

The sliver gate is fitted on both families (`stages.fit_gate`): fitted on mazes alone it
left real targets behind in office floors and made routes longer there.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, cast

import cv2
import numpy as np

from pipeline.world.map_files import MAX_IMAGE_PIXELS
from pipeline.world.mazes import FREE_VALUE, START_VALUE, WALL_VALUE, generate_map_set

OFFICE_SCALES = ("maze", "real_robot")  # the sizes of `OfficeConfig.for_scale`
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
    lattice_m: float = 4.0  # the lattice the floors are drawn for: each door lets a lattice line through

    @classmethod
    def real_robot(cls, side_m: float = 60.0, cell_size: float = 0.2) -> "OfficeConfig":
        """Office floors at building sizes for the real-robot scale (Sec. V-C: 0.2 m cells, 1 m lattice)."""
        return cls(
            side_m=side_m,
            cell_size=cell_size,
            wall_m=(0.1, 0.3),
            door_m=(0.8, 1.6),
            min_room_m=3.0,
            split_above_m=8.0,
            max_depth=10,
            stop_chance=0.15,
            clutter=(0, 3),
            clutter_m=(0.4, 1.2),
            clutter_margin_m=1.2,
            lattice_m=1.0,
        )

    @classmethod
    def for_scale(cls, scale: str, side_m: float = 100.0, cell_size: float = 0.4) -> "OfficeConfig":
        """`maze`: the sizes a 4 m lattice passes (the maze benchmark's scale); `real_robot`: building sizes."""
        if scale not in OFFICE_SCALES:
            raise ValueError(f"office scale must be one of {', '.join(OFFICE_SCALES)}, got {scale!r}")
        return cls.real_robot(side_m, cell_size) if scale == "real_robot" else cls(side_m=side_m, cell_size=cell_size)

    @property
    def aligns_doors(self) -> bool:
        """Whether doors are placed over lattice lines: some are too narrow to always hold one."""
        return self.door_m[0] < self.lattice_m + 2 * self.cell_size

    def __post_init__(self) -> None:
        if not self.cell_size > 0 or not self.side_m >= 20:
            raise ValueError(
                f"OfficeConfig needs cell_size > 0 and side_m >= 20 m, got {self.cell_size}, {self.side_m}"
            )
        for name in ("wall_m", "door_m", "clutter", "clutter_m"):
            low, high = getattr(self, name)
            if not 0 <= low <= high:
                raise ValueError(
                    f"OfficeConfig.{name} must be a range low <= high of non-negative values, got {(low, high)}"
                )
        if self.aligns_doors:
            step = self.lattice_m / self.cell_size
            if not (step >= 2 and abs(step - round(step)) < 1e-9):
                raise ValueError(
                    f"OfficeConfig.lattice_m ({self.lattice_m:g} m) must be a whole number (2 or more) of "
                    f"cells ({self.cell_size:g} m) for doors narrower than it to be placed over its lines"
                )
            if self.cells(self.wall_m[1]) >= round(step):
                raise ValueError(
                    f"OfficeConfig.wall_m must stay thinner than lattice_m ({self.lattice_m:g} m): walls "
                    f"sit between lattice lines, got {self.wall_m}"
                )
            if self.door_m[0] < 2 * self.cell_size:
                raise ValueError(f"OfficeConfig.door_m must start at two cells or more, got {self.door_m}")
        if (2 * self.cells(self.side_m)) ** 2 > MAX_IMAGE_PIXELS:
            largest = math.isqrt(MAX_IMAGE_PIXELS) // 2 * self.cell_size
            raise ValueError(
                f"office floors of {self.side_m:g} m make an image of more than the map loader reads; "
                f"the largest side at {self.cell_size:g} m cells is {largest:.0f} m"
            )
        if not 2 * self.min_room_m <= self.split_above_m:
            raise ValueError(
                "OfficeConfig.split_above_m must be at least twice min_room_m (both halves of a split fit)"
            )

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
    # Narrow doors: the lattice's phase (row, col residues of its lines) is drawn first, each door
    # is placed over one of its lines, and the start (which fixes the lattice) sits on that phase.
    step = config.cells(config.lattice_m)
    phase = cast(tuple[int, int], tuple(int(v) for v in rng.integers(0, step, size=2))) if config.aligns_doors else None

    def wall_start(low: int, high: int, wall: int, line_phase: int) -> int:
        """A wall's first cell in [low, high): anywhere, or (aligned) between two lattice lines, so
        that no wall lies along a line and the lines cross walls only at their doors."""
        if phase is None:
            return int(rng.integers(low, high))
        starts = np.arange(low, high)
        offset = (starts - line_phase) % step  # the wall's cells start..start+wall-1 miss every line
        starts = starts[(offset >= 1) & (offset <= step - wall)]
        return int(rng.choice(starts)) if starts.size else int(rng.integers(low, high))

    def door_start(low: int, high: int, door: int, line_phase: int) -> int:
        """A door's first cell in [low, high): anywhere, or (aligned) so that a lattice line runs through it."""
        if phase is None:
            return int(rng.integers(low, high))
        starts = np.arange(low, high)
        starts = starts[(line_phase - starts) % step < door]  # some cell start..start+door-1 is on a line
        return int(rng.choice(starts)) if starts.size else int(rng.integers(low, high))

    def cells_in(bounds: tuple[float, float]) -> int:
        low, high = (config.cells(v) for v in bounds)
        return int(rng.integers(low, high + 1))

    def split(top: int, left: int, bottom: int, right: int, depth: int) -> None:
        height, width = bottom - top, right - left
        door = cells_in(config.door_m)
        if (
            depth >= config.max_depth
            or max(height, width) <= split_above
            or min(height, width) < door + 4
            or (depth > 2 and rng.random() < config.stop_chance)
        ):
            rooms.append((top, left, bottom, right))
            return
        wall = cells_in(config.wall_m)
        across_rows = height >= width  # cut the longer side
        low, high = (top, bottom) if across_rows else (left, right)
        cut = wall_start(
            low + min_room, high - min_room - wall + 1, wall, phase[0 if across_rows else 1] if phase else 0
        )
        span = (left, right) if across_rows else (top, bottom)
        doors = 1 + int(span[1] - span[0] > 3 * door + 10 and rng.random() < config.second_door_chance)
        if across_rows:
            free[cut : cut + wall, left:right] = False
        else:
            free[top:bottom, cut : cut + wall] = False
        for _ in range(doors):
            # A wall across rows holds doors along its columns, so the lattice's column lines cross it.
            start = door_start(span[0] + 2, span[1] - door - 1, door, phase[1 if across_rows else 0] if phase else 0)
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
    return free, _start_cell(free, rooms, rng, None if phase is None else (step, phase))


def _start_cell(
    free: np.ndarray,
    rooms: list[tuple[int, int, int, int]],
    rng: np.random.Generator,
    lattice: tuple[int, tuple[int, int]] | None = None,
) -> tuple[int, int]:
    """A start in a random room, with free cells all around the START_CELLS square that marks it
    (and, given `lattice` = (step, (row, col) phase), on a lattice node of that phase)."""
    clear = cv2.erode(free.astype(np.uint8), np.ones((2 * START_CELLS + 1,) * 2, np.uint8)).astype(bool)
    if lattice is not None:
        step, (row_phase, col_phase) = lattice
        cell_rows, cell_cols = np.indices(clear.shape)
        clear &= (cell_rows % step == row_phase) & (cell_cols % step == col_phase)
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


def draw_with_sides(
    draw_floor: Callable[[Any, np.random.Generator], np.ndarray],
    config: Any,
    side_m: tuple[float, float] | None,
    what: str,
) -> Callable[[np.random.Generator], np.ndarray]:
    """`generate_map_set`'s draw for a floor family: `draw_floor(config, rng)`, with (given `side_m` =
    (low, high)) each floor's side drawn first in whole metres from that range, inclusive; a side
    the config refuses fails here, before any floor is drawn."""
    if side_m is None:
        return lambda rng: draw_floor(config, rng)
    low, high = math.ceil(side_m[0]), math.floor(side_m[1])
    if not 20 <= low <= high:
        raise ValueError(f"{what} sides must be a range low <= high of at least 20 m, got {tuple(side_m)}")
    for side in (low, high):
        replace(config, side_m=float(side))
    return lambda rng: draw_floor(replace(config, side_m=float(rng.integers(low, high + 1))), rng)


def generate_office_set(
    config: OfficeConfig,
    count: int,
    out_dir: str | Path,
    seed: int | Sequence[int],
    prefix: str = "office",
    progress: bool = True,
    side_m: tuple[float, float] | None = None,
) -> list[Path]:
    """Write `count` office floors as `{prefix}_{i:04d}.png`, floor i drawn from default_rng([*seed, i]).

    With `side_m` = (low, high), each floor's side is drawn in whole metres from that range
    (inclusive) before the floor itself; else every floor has `config.side_m`.
    """
    draw = draw_with_sides(generate_office, config, side_m, "office floor")
    return generate_map_set(draw, count, out_dir, seed, prefix, progress)
