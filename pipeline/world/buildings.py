"""Procedural building floors drawn like real plans: a third map family, beside mazes and offices.

The office floors (`pipeline.world.offices`) keep every wall between two lattice lines, so no
interior wall ever lands on a lattice node and a node image of an office shows no interior wall.
An inpainter trained on them learns that the unknown is free. Real plans are not so tidy: a wall
lies wherever the architect put it, and at a 1 m lattice a 0.2 m wall covers a lattice line about
one time in five. A building floor here is drawn to have what real plans have:

- walls at any phase of the lattice, 0.1-0.3 m thick;
- doors of 0.7-1.2 m (each over a lattice line, so that a lattice robot can pass it: a door no
  line crosses closes its room to the robot);
- corridors (1.4-2.6 m) with rooms on both sides, and halls (parts left undivided);
- rooms that are not rectangles: partial walls that make L-shaped rooms, openings that merge two
  rooms, a cut corner of the outline, diagonal walls across some room corners;
- an outline that is not always a rectangle (a corner block left out);
- furniture that occludes the lidar: tables, shelves along walls, columns in halls, kept off
  the doors;
- sides of 20-80 m.

`draw_building` returns a label grid (free, wall, furniture, outside) so that the statistics that
decide what an inpainter learns can be measured on the family (`floor_statistics`). A room that
the lattice cannot reach (furniture or a wall across its only door's lattice line) is closed off
as solid, as a locked room is on a real plan.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pipeline.world.maps import MAX_IMAGE_PIXELS
from pipeline.world.mazes import generate_map_set
from pipeline.world.offices import START_CELLS, draw_with_sides, render_free_map

FREE_LABEL, WALL_LABEL, FURNITURE_LABEL, OUTSIDE_LABEL = 0, 1, 2, 3


@dataclass(frozen=True)
class BuildingConfig:
    """What kind of building floors to draw; lengths in metres, ranges inclusive."""

    side_m: float = 40.0
    cell_size: float = 0.2
    lattice_m: float = 1.0  # the lattice the floors are drawn for: each door lets one of its lines through
    wall_m: tuple[float, float] = (0.1, 0.3)  # interior wall thickness, at any phase of the lattice
    door_m: tuple[float, float] = (0.7, 1.2)  # door width
    corridor_m: tuple[float, float] = (1.4, 2.6)  # corridor width
    corridor_chance: float = 0.6  # the chance a part longer than `corridor_above_m` gets a corridor, not a wall
    corridor_above_m: float = 14.0  # parts longer than this may get a corridor with rooms on both sides
    min_room_m: float = 2.6  # no split leaves a room narrower than this
    split_above_m: float = 7.0  # a part whose longer side exceeds this is split (unless it stays a hall)
    hall_chance: float = 0.1  # from depth 2 on, the chance a part stays one big room (a hall)
    max_depth: int = 12
    merge_chance: float = 0.12  # the chance a split wall gets a wide opening (two rooms become one)
    stub_chance: float = 0.25  # the chance a room gets a partial wall (an L-shaped room)
    diagonal_chance: float = 0.15  # the chance a room gets a diagonal wall across one corner
    notch_chance: float = 0.5  # the chance the outline loses a corner block (an L-shaped floor)
    chamfer_chance: float = 0.3  # the chance the outline has one cut (diagonal) corner
    furniture: tuple[int, int] = (0, 4)  # pieces per room
    table_m: tuple[float, float] = (0.6, 1.8)  # table side
    shelf_m: tuple[float, float] = (0.3, 0.6)  # shelf depth (its length runs 1-3 m along a wall)
    column_m: tuple[float, float] = (0.3, 0.6)  # column side (halls: a row of columns)
    door_clearance_m: float = 1.0  # furniture keeps this far from every door

    def __post_init__(self) -> None:
        if not self.cell_size > 0 or not 20 <= self.side_m:
            raise ValueError(f"BuildingConfig needs cell_size > 0 and side_m >= 20 m, got {self.cell_size}, {self.side_m}")
        for name in ("wall_m", "door_m", "corridor_m", "furniture", "table_m", "shelf_m", "column_m"):
            low, high = getattr(self, name)
            if not 0 <= low <= high:
                raise ValueError(f"BuildingConfig.{name} must be a range low <= high of non-negative values, got {(low, high)}")
        step = self.lattice_m / self.cell_size
        if not (step >= 2 and abs(step - round(step)) < 1e-9):
            raise ValueError(f"BuildingConfig.lattice_m ({self.lattice_m:g} m) must be a whole number (2 or more) of "
                             f"cells ({self.cell_size:g} m): doors are placed over its lines")
        if self.cells(self.door_m[0]) < 2:
            raise ValueError(f"BuildingConfig.door_m must start at two cells or more, got {self.door_m}")
        if not 2 * self.min_room_m <= self.split_above_m:
            raise ValueError("BuildingConfig.split_above_m must be at least twice min_room_m (both halves of a split fit)")
        if (2 * self.cells(self.side_m)) ** 2 > MAX_IMAGE_PIXELS:
            largest = math.isqrt(MAX_IMAGE_PIXELS) // 2 * self.cell_size
            raise ValueError(f"building floors of {self.side_m:g} m make an image of more than the map loader reads; "
                             f"the largest side at {self.cell_size:g} m cells is {largest:.0f} m")

    def cells(self, metres: float) -> int:
        """A length in whole cells (at least one)."""
        return max(1, int(round(metres / self.cell_size)))


@dataclass(frozen=True)
class BuildingFloor:
    """One drawn floor: labels per cell, the start cell (row, col), the lattice it was drawn for,
    and its rooms and doors as cell rectangles (top, left, bottom, right), bottom/right exclusive."""

    labels: np.ndarray
    start: tuple[int, int]
    step: int  # lattice spacing in cells
    phase: tuple[int, int]  # (row, col) residues of the lattice lines
    rooms: tuple[tuple[int, int, int, int], ...]
    doors: tuple[tuple[int, int, int, int], ...]
    walls: tuple[tuple[int, int, int, int], ...]  # the interior axis-aligned wall runs, as drawn (before doors)

    @property
    def free(self) -> np.ndarray:
        return self.labels == FREE_LABEL


class _Drawing:
    """The state of one floor being drawn: the label grid, the random source, rooms, doors, walls."""

    def __init__(self, config: BuildingConfig, rng: np.random.Generator):
        self.config, self.rng = config, rng
        n = config.cells(config.side_m)
        self.labels = np.full((n, n), OUTSIDE_LABEL, dtype=np.uint8)
        self.step = config.cells(config.lattice_m)
        self.phase = (int(rng.integers(0, self.step)), int(rng.integers(0, self.step)))
        self.rooms: list[tuple[int, int, int, int]] = []
        self.doors: list[tuple[int, int, int, int]] = []
        self.walls: list[tuple[int, int, int, int]] = []

    def draw(self, metres: tuple[float, float]) -> int:
        low, high = (self.config.cells(v) for v in metres)
        return int(self.rng.integers(low, high + 1))

    def chance(self, p: float) -> bool:
        return bool(self.rng.random() < p)

    def wall(self, top: int, left: int, bottom: int, right: int) -> None:
        block = self.labels[top:bottom, left:right]
        block[block != OUTSIDE_LABEL] = WALL_LABEL
        self.walls.append((top, left, bottom, right))

    def door(self, along_rows: bool, cut: int, thickness: int, low: int, high: int) -> bool:
        """Open a door through the wall cells [cut, cut + thickness) of a wall running along
        `along_rows` (a horizontal wall) between `low` and `high`, over a lattice line; False
        when no line crosses the span."""
        width = self.draw(self.config.door_m)
        margin = self.config.cells(0.3)
        line_phase = self.phase[1] if along_rows else self.phase[0]
        starts = np.arange(low + margin, high - margin - width + 1)
        starts = starts[(line_phase - starts) % self.step < width]  # a lattice line runs through the door
        # Both sides of the door are inside the floor (not the outline's cut-away parts).
        before, after = max(cut - 1, 0), min(cut + thickness, self.labels.shape[0] - 1)
        sides = (self.labels[[before, after], :] if along_rows else self.labels[:, [before, after]].T) != OUTSIDE_LABEL
        inside = np.convolve(sides.all(axis=0).astype(int), np.ones(width, int), mode="valid") == width
        starts = starts[inside[starts]] if starts.size else starts
        if not starts.size:
            return False
        start = int(self.rng.choice(starts))
        rect = (cut, start, cut + thickness, start + width) if along_rows else (start, cut, start + width, cut + thickness)
        self.labels[rect[0] : rect[2], rect[1] : rect[3]] = FREE_LABEL
        self.doors.append(rect)
        return True


def _outline(drawing: _Drawing) -> tuple[int, int, int, int]:
    """Carve the floor's inside: a rectangle, less perhaps one corner block and one cut corner."""
    config, rng, labels = drawing.config, drawing.rng, drawing.labels
    n = labels.shape[0]
    outer = 2  # cells of outer wall
    labels[outer:-outer, outer:-outer] = FREE_LABEL
    labels[outer - 1, outer - 1 : n - outer + 1] = WALL_LABEL
    labels[n - outer, outer - 1 : n - outer + 1] = WALL_LABEL
    labels[outer - 1 : n - outer + 1, outer - 1] = WALL_LABEL
    labels[outer - 1 : n - outer + 1, n - outer] = WALL_LABEL
    if drawing.chance(config.notch_chance):  # an L-shaped floor: one corner block is not the building's
        block_h = int(rng.integers(n // 5, n * 2 // 5))
        block_w = int(rng.integers(n // 5, n * 2 // 5))
        corner = int(rng.integers(4))
        rows = slice(0, block_h) if corner < 2 else slice(n - block_h, n)
        cols = slice(0, block_w) if corner % 2 == 0 else slice(n - block_w, n)
        labels[rows, cols] = OUTSIDE_LABEL
    if drawing.chance(config.chamfer_chance):  # one corner cut on the diagonal
        size = int(rng.integers(n // 8, n // 4))
        corner = int(rng.integers(4))
        rows, cols = np.indices(labels.shape)
        r = rows if corner < 2 else n - 1 - rows
        c = cols if corner % 2 == 0 else n - 1 - cols
        labels[r + c < size] = OUTSIDE_LABEL
    # The wall ring along whatever outline is left: free cells next to outside become wall.
    free = labels == FREE_LABEL
    outside = (labels == OUTSIDE_LABEL).astype(np.uint8)
    ring = cv2.dilate(outside, np.ones((3, 3), np.uint8)).astype(bool) & free
    labels[ring] = WALL_LABEL
    return outer, outer, n - outer, n - outer


def _split(drawing: _Drawing, top: int, left: int, bottom: int, right: int, depth: int) -> None:
    """Recursive division of the part [top, bottom) x [left, right) into rooms, corridors and halls."""
    config, rng = drawing.config, drawing.rng
    height, width = bottom - top, right - left
    min_room, split_above = config.cells(config.min_room_m), config.cells(config.split_above_m)
    inside = drawing.labels[top:bottom, left:right] != OUTSIDE_LABEL
    if not inside.any():
        return
    if (depth >= config.max_depth or max(height, width) <= split_above
            or (depth >= 2 and drawing.chance(config.hall_chance))):
        drawing.rooms.append((top, left, bottom, right))
        return
    across_rows = height >= width  # cut across the longer side
    length = height if across_rows else width
    if length < 2 * min_room + config.cells(config.wall_m[1]):
        drawing.rooms.append((top, left, bottom, right))
        return
    low, high = (top, bottom) if across_rows else (left, right)
    span = (left, right) if across_rows else (top, bottom)
    if length > config.cells(config.corridor_above_m) and drawing.chance(config.corridor_chance):
        corridor = drawing.draw(config.corridor_m)
        wall_a, wall_b = drawing.draw(config.wall_m), drawing.draw(config.wall_m)
        total = wall_a + corridor + wall_b
        cut = int(rng.integers(low + min_room, high - min_room - total + 1))
        first, second = (cut, cut + wall_a), (cut + wall_a + corridor, cut + total)
        for start, end in (first, second):
            if across_rows:
                drawing.wall(start, left, end, right)
            else:
                drawing.wall(top, start, bottom, end)
        # Rooms on both sides get their doors onto the corridor once they are drawn.
        before = len(drawing.rooms)
        if across_rows:
            _split(drawing, top, left, first[0], right, depth + 1)
        else:
            _split(drawing, top, left, bottom, first[0], depth + 1)
        _corridor_doors(drawing, drawing.rooms[before:], across_rows, first, side_before=True)
        before = len(drawing.rooms)
        if across_rows:
            _split(drawing, second[1], left, bottom, right, depth + 1)
        else:
            _split(drawing, top, second[1], bottom, right, depth + 1)
        _corridor_doors(drawing, drawing.rooms[before:], across_rows, second, side_before=False)
        corridor_rect = (first[1], left, second[0], right) if across_rows else (top, first[1], bottom, second[0])
        drawing.rooms.append(corridor_rect)
        return
    thickness = drawing.draw(config.wall_m)
    cut = int(rng.integers(low + min_room, high - min_room - thickness + 1))
    if across_rows:
        drawing.wall(cut, left, cut + thickness, right)
    else:
        drawing.wall(top, cut, bottom, cut + thickness)
    if drawing.chance(config.merge_chance) and span[1] - span[0] > 3 * min_room:
        # A wide opening: the two sides read as one irregular room.
        opening = int(rng.integers(span[1] - span[0]) // 3 + min_room)
        start = int(rng.integers(span[0] + 1, span[1] - opening))
        rect = (cut, start, cut + thickness, start + opening) if across_rows else (start, cut, start + opening, cut + thickness)
        block = drawing.labels[rect[0] : rect[2], rect[1] : rect[3]]
        block[block == WALL_LABEL] = FREE_LABEL
        drawing.doors.append(rect)
    else:
        drawing.door(across_rows, cut, thickness, *span)
    if across_rows:
        _split(drawing, top, left, cut, right, depth + 1)
        _split(drawing, cut + thickness, left, bottom, right, depth + 1)
    else:
        _split(drawing, top, left, bottom, cut, depth + 1)
        _split(drawing, top, cut + thickness, bottom, right, depth + 1)


def _corridor_doors(drawing: _Drawing, rooms: list[tuple[int, int, int, int]], across_rows: bool,
                    wall: tuple[int, int], side_before: bool) -> None:
    """A door from each room along a corridor wall (cells wall[0]..wall[1]) into the corridor."""
    for top, left, bottom, right in rooms:
        touches = (bottom == wall[0]) if side_before else (top == wall[1])
        if not across_rows:
            touches = (right == wall[0]) if side_before else (left == wall[1])
        if touches:
            low, high = (left, right) if across_rows else (top, bottom)
            drawing.door(across_rows, wall[0], wall[1] - wall[0], low, high)


def _shape_rooms(drawing: _Drawing) -> None:
    """Make some rooms irregular: a partial wall (an L-shaped room) or a diagonal wall across a corner."""
    config, rng, labels = drawing.config, drawing.rng, drawing.labels
    min_room = config.cells(config.min_room_m)
    for top, left, bottom, right in list(drawing.rooms):
        height, width = bottom - top, right - left
        if min(height, width) < 2 * min_room + config.cells(config.wall_m[1]):
            continue
        if drawing.chance(config.stub_chance):
            thickness = drawing.draw(config.wall_m)
            if height >= width:  # a stub across the room from its left or right wall
                row = int(rng.integers(top + min_room, bottom - min_room - thickness + 1))
                reach = int(width * rng.uniform(0.4, 0.7))
                cols = (left, left + reach) if drawing.chance(0.5) else (right - reach, right)
                drawing.wall(row, cols[0], row + thickness, cols[1])
            else:
                col = int(rng.integers(left + min_room, right - min_room - thickness + 1))
                reach = int(height * rng.uniform(0.4, 0.7))
                rows = (top, top + reach) if drawing.chance(0.5) else (bottom - reach, bottom)
                drawing.wall(rows[0], col, rows[1], col + thickness)
        elif drawing.chance(config.diagonal_chance):
            size = int(min(height, width) * rng.uniform(0.3, 0.5))
            corner = int(rng.integers(4))
            r0 = top if corner < 2 else bottom - 1
            c0 = left if corner % 2 == 0 else right - 1
            dr = 1 if corner < 2 else -1
            dc = 1 if corner % 2 == 0 else -1
            thickness = drawing.draw(config.wall_m)
            wall = np.zeros(labels.shape, np.uint8)
            cv2.line(wall, (c0 + dc * size, r0), (c0, r0 + dr * size), 1, thickness=max(1, thickness))
            labels[(wall > 0) & (labels == FREE_LABEL)] = WALL_LABEL


def _furnish(drawing: _Drawing) -> None:
    """Tables, shelves along walls and (in large rooms) a row of columns, kept off the doors."""
    config, rng, labels = drawing.config, drawing.rng, drawing.labels
    keep_clear = np.zeros(labels.shape, dtype=bool)
    clearance = config.cells(config.door_clearance_m)
    n = labels.shape[0]
    for top, left, bottom, right in drawing.doors:
        keep_clear[max(0, top - clearance) : min(n, bottom + clearance), max(0, left - clearance) : min(n, right + clearance)] = True
    corridors = {room for room in drawing.rooms if min(room[2] - room[0], room[3] - room[1]) <= config.cells(config.corridor_m[1])}

    def place(top: int, left: int, height: int, width: int) -> None:
        block = (slice(top, top + height), slice(left, left + width))
        if height > 0 and width > 0 and (labels[block] == FREE_LABEL).all() and not keep_clear[block].any():
            labels[block] = FURNITURE_LABEL

    for room in drawing.rooms:
        top, left, bottom, right = room
        if room in corridors:
            continue
        height, width = bottom - top, right - left
        for _ in range(int(rng.integers(config.furniture[0], config.furniture[1] + 1))):
            kind = rng.random()
            if kind < 0.5:  # a table, away from the walls
                h, w = drawing.draw(config.table_m), drawing.draw(config.table_m)
                if height - h > 6 and width - w > 6:
                    place(int(rng.integers(top + 3, bottom - h - 2)), int(rng.integers(left + 3, right - w - 2)), h, w)
            else:  # a shelf along one of the room's walls
                depth, length = drawing.draw(config.shelf_m), drawing.draw((1.0, 3.0))
                side = int(rng.integers(4))
                if side < 2 and width > length + 2:
                    col = int(rng.integers(left, right - length))
                    place(top if side == 0 else bottom - depth, col, depth, length)
                elif side >= 2 and height > length + 2:
                    row = int(rng.integers(top, bottom - length))
                    place(row, left if side == 2 else right - depth, length, depth)
        if min(height, width) > config.cells(8.0):  # a hall: a row of columns down its middle
            size = drawing.draw(config.column_m)
            spacing = config.cells(float(rng.uniform(3.0, 5.0)))
            if height >= width:
                col = (left + right) // 2
                for row in range(top + spacing, bottom - spacing, spacing):
                    place(row, col, size, size)
            else:
                row = (top + bottom) // 2
                for col in range(left + spacing, right - spacing, spacing):
                    place(row, col, size, size)


def lattice_reachable(free: np.ndarray, start: tuple[int, int], step: int) -> np.ndarray:
    """Lattice nodes (on the start's lattice) a robot reaches from `start` moving between
    4-neighbouring nodes over free cells only: a boolean grid, True at reached node cells."""
    rows, cols = free.shape
    r0, c0 = start[0] % step, start[1] % step
    node_rows, node_cols = np.arange(r0, rows, step), np.arange(c0, cols, step)
    node_free = free[np.ix_(node_rows, node_cols)]
    # Edges: every cell between two neighbouring nodes is free.
    down = np.ones((len(node_rows) - 1, len(node_cols)), dtype=bool)
    for k in range(step + 1):
        down &= free[np.ix_(node_rows[:-1] + k, node_cols)] if k < step else free[np.ix_(node_rows[1:], node_cols)]
    right = np.ones((len(node_rows), len(node_cols) - 1), dtype=bool)
    for k in range(step + 1):
        right &= free[np.ix_(node_rows, node_cols[:-1] + k)] if k < step else free[np.ix_(node_rows, node_cols[1:])]
    reached = np.zeros_like(node_free)
    i, j = (start[0] - r0) // step, (start[1] - c0) // step
    if not node_free[i, j]:
        return np.zeros(free.shape, dtype=bool)
    reached[i, j] = True
    frontier = [(i, j)]
    while frontier:
        a, b = frontier.pop()
        for da, db, edge in ((1, 0, down), (-1, 0, down), (0, 1, right), (0, -1, right)):
            na, nb = a + da, b + db
            if not (0 <= na < reached.shape[0] and 0 <= nb < reached.shape[1]) or reached[na, nb]:
                continue
            ea, eb = min(a, na), min(b, nb)
            if edge[ea, eb]:
                reached[na, nb] = True
                frontier.append((na, nb))
    grid = np.zeros(free.shape, dtype=bool)
    grid[np.ix_(node_rows, node_cols)] = reached
    return grid


def _pick_start(drawing: _Drawing) -> tuple[int, int]:
    """A start cell on the lattice phase, in a room, with free cells around its START_CELLS square."""
    free = drawing.labels == FREE_LABEL
    clear = cv2.erode(free.astype(np.uint8), np.ones((2 * START_CELLS + 1,) * 2, np.uint8)).astype(bool)
    rows, cols = np.indices(clear.shape)
    clear &= (rows % drawing.step == drawing.phase[0]) & (cols % drawing.step == drawing.phase[1])
    candidates = np.argwhere(clear)
    if not len(candidates):
        raise RuntimeError("building generator bug: no free lattice node has room for the start")
    row, col = candidates[int(drawing.rng.integers(len(candidates)))]
    return int(row), int(col)


def _close_unreachable(drawing: _Drawing, start: tuple[int, int]) -> float:
    """Free space the lattice robot cannot reach leaves the floor (a locked room: solid on the map,
    outside in the labels), and the free space left is the start's 4-connected part; the share of
    the free space closed."""
    labels = drawing.labels
    free = labels == FREE_LABEL
    reached = lattice_reachable(free, start, drawing.step)
    _, parts = cv2.connectedComponents(free.astype(np.uint8), connectivity=4)
    # A free part with no reached node, or a room no reached node lies in, is closed.
    reached_parts = np.unique(parts[reached])
    closed = free & ~np.isin(parts, reached_parts)
    for top, left, bottom, right in drawing.rooms:
        if not reached[top:bottom, left:right].any():
            closed[top:bottom, left:right] |= free[top:bottom, left:right]
    labels[closed] = OUTSIDE_LABEL
    _, parts = cv2.connectedComponents((labels == FREE_LABEL).astype(np.uint8), connectivity=4)
    labels[(labels == FREE_LABEL) & (parts != parts[start])] = OUTSIDE_LABEL
    return 1.0 - float((labels == FREE_LABEL).sum()) / max(1, int(free.sum()))


MAX_CLOSED_SHARE = 0.1  # a floor that loses more of its free space to locked rooms is drawn again
DRAW_ATTEMPTS = 10


def draw_building(config: BuildingConfig, rng: np.random.Generator) -> BuildingFloor:
    """One building floor: labels (free, wall, furniture, outside), start, lattice, rooms, doors.

    A floor whose locked rooms (`_close_unreachable`) take more than MAX_CLOSED_SHARE of its
    free space is drawn again from the same random source (at most DRAW_ATTEMPTS times), so that
    a floor's size is about its side's."""
    for _ in range(DRAW_ATTEMPTS):
        drawing = _Drawing(config, rng)
        bounds = _outline(drawing)
        _split(drawing, *bounds, depth=0)
        _shape_rooms(drawing)
        _furnish(drawing)
        start = _pick_start(drawing)
        if _close_unreachable(drawing, start) <= MAX_CLOSED_SHARE:
            break
    return BuildingFloor(drawing.labels, start, drawing.step, drawing.phase, tuple(drawing.rooms),
                         tuple(drawing.doors), tuple(drawing.walls))


def generate_building(config: BuildingConfig, rng: np.random.Generator) -> np.ndarray:
    """Draw one building floor as a maze PNG image (127 wall, 195 free, 208 start square)."""
    floor = draw_building(config, rng)
    return render_free_map(floor.free, floor.start)


def generate_building_set(config: BuildingConfig, count: int, out_dir: str | Path, seed: int | Sequence[int],
                          prefix: str = "building", progress: bool = True,
                          side_m: tuple[float, float] | None = None) -> list[Path]:
    """Write `count` building floors as `{prefix}_{i:04d}.png`, floor i drawn from default_rng([*seed, i]);
    with `side_m` = (low, high), each floor's side in whole metres is drawn from that range first."""
    draw = draw_with_sides(generate_building, config, side_m, "building floor")
    return generate_map_set(draw, count, out_dir, seed, prefix, progress)


def floor_statistics(floor: BuildingFloor, cell_size: float) -> dict[str, float]:
    """What decides what an inpainter learns from a floor, measured on its labels and lattice:

    - `wall_runs_on_nodes`: the share of interior wall runs (as drawn) that cover a lattice node;
    - `nodes_on_walls`: the share of the lattice nodes inside the outline that are wall cells;
    - `nodes_on_furniture`: the same for furniture;
    - `free_share`: free cells over the cells inside the outline;
    - `door_m`: the mean door width (openings that merge rooms left out);
    - `room_m2`: the median room area (corridors included), from the rooms as drawn.
    """
    labels, step, (row_phase, col_phase) = floor.labels, floor.step, floor.phase
    nodes = labels[row_phase::step, col_phase::step]
    inside = nodes != OUTSIDE_LABEL
    node_grid = np.zeros(labels.shape, dtype=bool)
    node_grid[row_phase::step, col_phase::step] = True
    on_nodes = [node_grid[t:b, l:r].any() for t, l, b, r in floor.walls]
    doors = [max(b - t, r - l) if min(b - t, r - l) <= 2 else min(b - t, r - l) for t, l, b, r in floor.doors]
    door_widths = [d * cell_size for d in doors if d * cell_size <= 1.5]
    inside_cells = labels != OUTSIDE_LABEL
    return {
        "wall_runs_on_nodes": float(np.mean(on_nodes)) if on_nodes else 0.0,
        "nodes_on_walls": float((nodes[inside] == WALL_LABEL).mean()),
        "nodes_on_furniture": float((nodes[inside] == FURNITURE_LABEL).mean()),
        "free_share": float((labels == FREE_LABEL).sum() / max(1, inside_cells.sum())),
        "door_m": float(np.mean(door_widths)) if door_widths else float("nan"),
        "room_m2": (float(np.median([(b - t) * (r - l) for t, l, b, r in floor.rooms])) * cell_size**2
                    if floor.rooms else float("nan")),
    }
