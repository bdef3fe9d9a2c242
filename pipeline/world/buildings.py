"""Procedural building floors drawn like real plans: a third map family, beside mazes and offices.

An inpainter learns what unknown space looks like from the floors it is trained on, so this
family is drawn to have the proportions of real floor plans: the defaults were set on the 14 KTH
plans in data/real_plans/kth/, measured the same way on both (`floor_statistics`, after
`pipeline.world.floor_shape.plan_statistics`; `benchmarks/floor_statistics.py` sets them side
by side). A building floor has:

- a footprint made of wings about 9-17 m deep, joined into bars, deep blocks with two
  corridors, L, T, U, E, H and cross shapes and courtyard rings, so that its bounding box is
  elongated (long side over short side about 1.5-5) and not always filled (courtyards and the
  space between wings are outside); its outer wall has bays, recesses and sometimes a cut corner;
- a corridor (1.4-2.4 m) down each wing with rooms on both sides (on one side in a few wings),
  the corridors of crossing wings joined, a corridor ending at the outer wall or at a room
  across the wing's end;
- rooms cut from the strips beside the corridors by cross walls: most 2-4 m wide (offices, WCs,
  store rooms), some large (labs, lecture rooms), a few halls; some deep rooms split into a
  front room and a back room behind it; now and then a room open to its corridor (a lobby);
- one door per room (0.7-1.2 m, anywhere along a wall, onto a corridor or, for a room with no
  corridor wall, into a neighbouring room), a second door in a few small rooms and in most
  large ones;
- walls 0.1-0.3 m thick at any phase of the lattice (the planners pass doors through the
  door-aware graph, so a door need not lie over a lattice line);
- furniture that occludes the lidar: tables, shelves along walls, partial walls and columns in
  large rooms, kept clear of the doors and never cutting a room in two.

Lengths become cells as the plan import makes them of a real plan (`pipeline.world.resample`):
a wall covers every cell it touches at a random phase (0.1-0.3 m: 1-3 cells of 0.2 m), a door
or a corridor frees only the cells wholly inside it (a 0.7-1.2 m door: 2-5 cells).

Every free cell is reachable from the start by a robot of `robot_radius_m`
(`pipeline.world.reachability.reachable_free`); anything else is closed off as solid (outside,
in the labels), as a locked room is on a real plan.

`draw_building` returns a label grid (free, wall, furniture, outside) with the room labels, so
that what decides what an inpainter learns can be measured on the family as on real plans.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from pipeline.world.floor_shape import plan_statistics
from pipeline.world.maps import MAX_IMAGE_PIXELS
from pipeline.world.mazes import generate_map_set
from pipeline.world.offices import START_CELLS, draw_with_sides, render_free_map
from pipeline.world.reachability import reachable_free

FREE_LABEL, WALL_LABEL, FURNITURE_LABEL, OUTSIDE_LABEL = 0, 1, 2, 3
CORRIDOR = -1  # region of corridor cells (and lobbies): free space that is no room
SHAPES = ("bar", "block", "L", "T", "U", "E", "H", "cross", "ring")

Rect = tuple[int, int, int, int]  # (top, left, bottom, right) cells, bottom/right exclusive


@dataclass(frozen=True)
class BuildingConfig:
    """What kind of building floors to draw; lengths in metres, ranges inclusive.

    `side_m` is the side of the square image; the building's longer side is 85-100 % of it.
    """

    side_m: float = 40.0
    cell_size: float = 0.2
    lattice_m: float = 1.0  # the lattice the planners run on: the start lies on one of its nodes
    robot_radius_m: float = 0.2  # every free cell is reachable from the start by a robot this wide
    wall_m: tuple[float, float] = (0.1, 0.3)  # interior wall thickness, at any phase of the lattice
    outer_wall_m: tuple[float, float] = (0.2, 0.4)  # outer wall thickness
    door_m: tuple[float, float] = (0.7, 1.2)  # door width
    corridor_m: tuple[float, float] = (1.4, 2.4)  # corridor width
    room_depth_m: tuple[float, float] = (3.5, 7.0)  # a strip of rooms, corridor wall to outer wall
    core_m: tuple[float, float] = (3.0, 8.0)  # the rooms between the two corridors of a deep block
    room_width_m: tuple[float, float] = (1.8, 3.6)  # most rooms' width along their corridor
    large_room_m: tuple[float, float] = (5.0, 16.0)  # a large room's width (a lab, a lecture room)
    large_room_chance: float = 0.28
    hall_m: tuple[float, float] = (8.0, 20.0)  # a hall's length along its wing
    hall_chance: float = 0.05  # the chance the next room along a strip is a hall
    end_room_chance: float = 0.5  # the chance a corridor ends at a room across its wing, not at the outer wall
    back_room_chance: float = 0.25  # the chance a deep room is split into a front room and a back room
    second_door_chance: float = 0.05  # the chance a room gets a second door
    large_door_chance: float = 0.55  # the chance a room of more than `large_room_m2` gets a second door (a
    # quarter of it: a third)
    large_room_m2: float = 25.0
    open_room_chance: float = 0.02  # the chance a room (of at most `large_room_m2`) opens onto its corridor over
    # its whole side (a lobby)
    single_loaded_chance: float = 0.08  # the chance a wing has rooms on one side of its corridor only
    shape_weights: tuple[float, ...] = (0.55, 0.06, 0.1, 0.05, 0.07, 0.05, 0.04, 0.02, 0.06)  # per SHAPES
    aspect: tuple[float, float] = (2.5, 6.0)  # long side over short side of a shape with crossing wings ...
    min_fill: tuple[float, float] = (0.6, 0.95)  # ... lowered until its wings fill at least this share of its box
    bays: tuple[int, int] = (0, 1)  # bays (stair towers, bay rooms) out of the outer wall
    bay_m: tuple[float, float] = (1.5, 3.5)
    recesses: tuple[int, int] = (0, 3)  # recesses into the outer wall
    recess_m: tuple[float, float] = (0.6, 2.0)  # recess depth (their length is 2-8 m)
    chamfer_chance: float = 0.15  # the chance one corner of the outline is cut on the diagonal
    stub_chance: float = 0.3  # the chance a large room gets a partial wall (an L-shaped room)
    furniture: tuple[int, int] = (0, 3)  # pieces per room
    table_m: tuple[float, float] = (0.6, 1.8)  # table side
    shelf_m: tuple[float, float] = (0.3, 0.6)  # shelf depth (its length runs 1-3 m along a wall)
    column_m: tuple[float, float] = (0.3, 0.6)  # column side (halls: a row of columns)
    door_clearance_m: float = 0.6  # furniture keeps this far from every door

    def __post_init__(self) -> None:
        if not self.cell_size > 0 or not 20 <= self.side_m:
            raise ValueError(f"BuildingConfig needs cell_size > 0 and side_m >= 20 m, "
                             f"got {self.cell_size}, {self.side_m}")
        for name in ("wall_m", "outer_wall_m", "door_m", "corridor_m", "room_depth_m", "core_m", "room_width_m",
                     "large_room_m", "hall_m", "aspect", "min_fill", "bays", "bay_m", "recesses", "recess_m",
                     "furniture", "table_m", "shelf_m", "column_m"):
            low, high = getattr(self, name)
            if not 0 <= low <= high:
                raise ValueError(f"BuildingConfig.{name} must be a range low <= high of non-negative values, "
                             f"got {(low, high)}")
        step = self.lattice_m / self.cell_size
        if not (step >= 2 and abs(step - round(step)) < 1e-9):
            raise ValueError(f"BuildingConfig.lattice_m ({self.lattice_m:g} m) must be a whole number (2 or more) of "
                             f"cells ({self.cell_size:g} m): the start is placed on its nodes")
        if self.cells(self.door_m[0]) < 2:
            raise ValueError(f"BuildingConfig.door_m must start at two cells or more, got {self.door_m}")
        if self.door_m[1] + 0.4 > self.room_width_m[0] or self.room_depth_m[0] < 2 * self.door_m[1]:
            raise ValueError("BuildingConfig.room_width_m must start 0.4 m above the widest door and room_depth_m "
                             "at twice it, so that every room has a wall a door fits in")
        if len(self.shape_weights) != len(SHAPES) or min(self.shape_weights) < 0 or sum(self.shape_weights) <= 0:
            raise ValueError(f"BuildingConfig.shape_weights needs one non-negative weight per shape {SHAPES}")
        if self.aspect[0] < 1:
            raise ValueError(f"BuildingConfig.aspect is long side over short side, 1 or more, got {self.aspect}")
        if (2 * self.cells(self.side_m)) ** 2 > MAX_IMAGE_PIXELS:
            largest = math.isqrt(MAX_IMAGE_PIXELS) // 2 * self.cell_size
            raise ValueError(f"building floors of {self.side_m:g} m make an image of more than the map loader reads; "
                             f"the largest side at {self.cell_size:g} m cells is {largest:.0f} m")

    def cells(self, metres: float) -> int:
        """A length in whole cells (at least one)."""
        return max(1, int(round(metres / self.cell_size)))


@dataclass(frozen=True)
class BuildingFloor:
    """One drawn floor: labels per cell, the start cell (row, col), the lattice the start lies on,
    its rooms (bounding rectangles, room i + 1's at index i), doors and the interior wall runs as
    drawn, as cell rectangles (top, left, bottom, right), bottom/right exclusive, and the room
    labels per cell (0 = no room: corridors, lobbies, doors, walls; i + 1 = room i)."""

    labels: np.ndarray
    start: tuple[int, int]
    step: int  # lattice spacing in cells
    phase: tuple[int, int]  # (row, col) residues of the lattice lines: the start's
    rooms: tuple[Rect, ...]
    doors: tuple[Rect, ...]
    walls: tuple[Rect, ...]
    room_labels: np.ndarray | None = field(default=None, repr=False)

    @property
    def free(self) -> np.ndarray:
        return self.labels == FREE_LABEL


@dataclass
class _Wing:
    """One wing of the footprint: its rectangle, whether it runs along the rows (a horizontal
    wing, its corridor along its length), its profile across (each corridor's offset and width
    from the wing's near side), and then its corridor rectangles and the positions along it where
    a cross wall is forced (where a corridor ends inside the wing: the end room's wall)."""

    rect: Rect
    horizontal: bool
    spans: list[tuple[int, int]]
    corridors: list[Rect] = field(default_factory=list)
    caps: list[int] = field(default_factory=list)


class _Drawing:
    """The state of one floor being drawn: labels, regions (CORRIDOR, 0 for wall and outside,
    room ids from 1), the random source and what has been drawn."""

    def __init__(self, config: BuildingConfig, rng: np.random.Generator):
        self.config, self.rng = config, rng
        self.n = config.cells(config.side_m)
        self.labels = np.full((self.n, self.n), OUTSIDE_LABEL, dtype=np.uint8)
        self.region = np.zeros((self.n, self.n), dtype=np.int32)
        self.step = config.cells(config.lattice_m)
        self.doors: list[Rect] = []
        self.walls: list[Rect] = []
        self.wall_cells = int(math.ceil(config.wall_m[1] / config.cell_size)) + 1  # the thickest wall drawn
        self.corridor_wall = 1  # the thickness of the corridors' walls, drawn per floor
        self.boxes: dict[int, Rect] = {}  # each room's bounding rectangle, once the rooms are cut

    def draw(self, metres: tuple[float, float]) -> int:
        low, high = (self.config.cells(v) for v in metres)
        return int(self.rng.integers(low, high + 1))

    def draw_wall(self, metres: tuple[float, float]) -> int:
        """The cells a wall of a thickness drawn from `metres` covers at a random phase of the
        cells: every cell it touches, as the plan import rasterises real plans (`resample_map`)."""
        thickness = self.rng.uniform(*metres) / self.config.cell_size
        return max(1, int(math.ceil(thickness + self.rng.random())))

    def draw_opening(self, metres: tuple[float, float]) -> int:
        """The cells an opening (a door, a corridor) of a width drawn from `metres` frees at a
        random phase of the cells: only those wholly inside it, as the plan import rasterises
        real plans."""
        width = self.rng.uniform(*metres) / self.config.cell_size
        return max(2, int(math.floor(width - (1.0 - self.rng.random()))))

    def chance(self, p: float) -> bool:
        return bool(self.rng.random() < p)

    def wall(self, rect: Rect, inside: np.ndarray | None = None) -> None:
        """Wall over the free cells of `rect` (those of `inside` too, when given)."""
        top, left, bottom, right = rect
        block = (slice(max(0, top), bottom), slice(max(0, left), right))
        cells = self.labels[block] == FREE_LABEL
        if inside is not None:
            cells &= inside[block]
        self.labels[block][cells] = WALL_LABEL
        self.region[block][cells] = 0
        if cells.any():
            self.walls.append(rect)


def _room_boxes(region: np.ndarray) -> dict[int, Rect]:
    """Each room's bounding rectangle, by room id."""
    rows, cols = np.nonzero(region > 0)
    ids = region[rows, cols]
    order = np.argsort(ids, kind="stable")
    ids, rows, cols = ids[order], rows[order], cols[order]
    if not len(ids):
        return {}
    starts = np.flatnonzero(np.r_[True, ids[1:] != ids[:-1]])
    tops, bottoms = np.minimum.reduceat(rows, starts), np.maximum.reduceat(rows, starts) + 1
    lefts, rights = np.minimum.reduceat(cols, starts), np.maximum.reduceat(cols, starts) + 1
    return {int(ids[s]): (int(top), int(left), int(bottom), int(right))
            for s, top, left, bottom, right in zip(starts, tops, lefts, bottoms, rights)}


def _crop(box: Rect) -> tuple[slice, slice]:
    """The slices of a rectangle."""
    return slice(box[0], box[2]), slice(box[1], box[3])


# ---------------------------------------------------------------------------- the footprint
def _wing_profile(drawing: _Drawing, outer: int, wall: int, deep: bool = False) -> tuple[int, list[tuple[int, int]]]:
    """A wing's depth across and its corridors as (offset, width) across it: rooms on both sides
    of one corridor, on one side only, or (`deep`) rooms, corridor, core rooms, corridor, rooms."""
    config = drawing.config
    first = drawing.draw(config.room_depth_m)
    corridor = drawing.draw_opening(config.corridor_m)
    if deep:
        core, last = drawing.draw(config.core_m), drawing.draw(config.room_depth_m)
        second_corridor = drawing.draw_opening(config.corridor_m)
        offset_a = outer + first + wall
        offset_b = offset_a + corridor + wall + core + wall
        return offset_b + second_corridor + wall + last + outer, [(offset_a, corridor), (offset_b, second_corridor)]
    if drawing.chance(config.single_loaded_chance):
        if drawing.chance(0.5):  # the corridor along the outer wall on one side
            return outer + corridor + wall + first + outer, [(outer, corridor)]
        return outer + first + wall + corridor + outer, [(outer + first + wall, corridor)]
    last = drawing.draw(config.room_depth_m)
    return outer + first + wall + corridor + wall + last + outer, [(outer + first + wall, corridor)]


def _layout(drawing: _Drawing, outer: int) -> list[_Wing]:
    """The wings of one floor in the image's frame: a shape from SHAPES, sized to the image,
    turned and mirrored at random and placed anywhere in it.

    Every shape but the bar and the block has one horizontal main wing (two for the ring) and
    wings crossing it, each running across the main wing's full depth: hanging from it (L, T, U,
    E) or through it (H, cross; the main wing across the middle), or joining two (the ring). Its
    height comes from `aspect`, lowered until the wings fill at least `min_fill` of their
    bounding box (real plans' footprints are elongated, but not sparse)."""
    config, rng = drawing.config, drawing.rng
    wall = drawing.corridor_wall
    span = drawing.n - 2  # one cell of outside all round
    weights = np.asarray(config.shape_weights, dtype=float)
    shape = SHAPES[int(rng.choice(len(SHAPES), p=weights / weights.sum()))]
    length = int(span * rng.uniform(0.85, 1.0))
    depth, across = _wing_profile(drawing, outer, wall, deep=shape == "block")
    depth = min(depth, span)
    cross = [_wing_profile(drawing, outer, wall) for _ in range(3)]
    if shape == "ring":
        cross.append(_wing_profile(drawing, outer, wall))
    widths = [d for d, _ in cross]
    margin = config.cells(4.0)  # the least a crossing wing reaches beyond the main wing
    needed = 2 * depth + margin if shape == "ring" else depth + (2 * margin if shape in ("H", "cross") else margin)
    arms = {"L": 1, "T": 1, "cross": 1, "U": 2, "H": 2, "ring": 2, "E": 3}.get(shape, 0)
    if shape in ("bar", "block") or needed > span or sum(widths[:arms]) + margin > length:
        return _placed(drawing, [_Wing((0, 0, depth, length), True, across)], outer)
    height = min(max(int(length / rng.uniform(*config.aspect)), needed), span)
    min_fill = rng.uniform(*config.min_fill)
    reach_share = [rng.uniform(0.5, 1.0) if shape in ("L", "U", "E", "T") and drawing.chance(0.4) else 1.0
                   for _ in range(3)]  # arms of unequal length
    if shape == "L":
        positions = [0 if drawing.chance(0.5) else length - widths[0]]
    elif shape in ("T", "cross"):
        positions = [int(rng.integers(0, length - widths[0] + 1))]
    elif shape == "E":
        positions = [0, int(rng.integers(widths[0], length - widths[2] - widths[1] + 1)), length - widths[2]]
    else:  # U, H, ring
        positions = [0, length - widths[1]]
    middle = rng.uniform(0.2, 0.8)
    while True:
        top = int(margin + (height - depth - 2 * margin) * middle) if shape in ("H", "cross") else 0
        wings = [_Wing((top, 0, top + depth, length), True, across)]
        if shape == "ring":
            wings.append(_Wing((height - widths[3], 0, height, length), True, cross[3][1]))
        for k, x in enumerate(positions):
            reach = max(top + depth + margin, int(height * reach_share[k]))
            wings.append(_Wing((0, x, reach, x + widths[k]), False, cross[k][1]))
        cover = np.zeros((height, length), dtype=bool)
        for w in wings:
            cover[w.rect[0] : w.rect[2], w.rect[1] : w.rect[3]] = True
        if cover.mean() >= min_fill or height <= needed:
            break
        height = max(needed, int(height * 0.9))
    return _placed(drawing, wings, outer)


def _placed(drawing: _Drawing, wings: list[_Wing], outer: int) -> list[_Wing]:
    """`wings` (in the shape's frame) with their corridors, moved to a random place in the image
    and turned by a random one of the 8 symmetries of the square."""
    rng, n, wall = drawing.rng, drawing.n, drawing.corridor_wall
    _corridors(drawing, wings, outer)
    span = n - 2
    bottom = max(w.rect[2] for w in wings)
    right = max(w.rect[3] for w in wings)
    dr = 1 + int(rng.integers(0, span - bottom + 1))
    dc = 1 + int(rng.integers(0, span - right + 1))
    transpose, flip_rows, flip_cols = (drawing.chance(0.5) for _ in range(3))
    for w in wings:
        w.rect = _place(w.rect, dr, dc, transpose, flip_rows, flip_cols, n)
        w.corridors = [_place(c, dr, dc, transpose, flip_rows, flip_cols, n) for c in w.corridors]
        caps = [c + (dc if w.horizontal else dr) for c in w.caps]  # a cap is a wall's first cell along the wing
        w.horizontal = w.horizontal != transpose
        if flip_cols if w.horizontal else flip_rows:
            caps = [n - c - wall for c in caps]
        w.caps = caps
    return wings


def _place(rect: Rect, dr: int, dc: int, transpose: bool, flip_rows: bool, flip_cols: bool, n: int) -> Rect:
    """A rectangle moved by (dr, dc), then transposed and mirrored inside the n x n image."""
    top, left, bottom, right = rect[0] + dr, rect[1] + dc, rect[2] + dr, rect[3] + dc
    top, left, bottom, right = (top, left, bottom, right) if not transpose else (left, top, right, bottom)
    if flip_rows:
        top, bottom = n - bottom, n - top
    if flip_cols:
        left, right = n - right, n - left
    return min(max(top, 0), n), min(max(left, 0), n), min(max(bottom, 0), n), min(max(right, 0), n)


def _corridors(drawing: _Drawing, wings: list[_Wing], outer: int) -> None:
    """Each wing's corridor rectangles, in the shape's frame, from its profile: a horizontal
    wing's corridor runs end to end, stopping at a crossing wing's corridor where that wing is
    flush with its end, else at the outer wall or before an end room; a crossing wing's runs from
    the horizontal corridors it meets to its ends (or to the outer wall or an end room beyond
    them). A corridor that stops inside its wing forces a cross wall there (`caps`)."""
    config, wall = drawing.config, drawing.corridor_wall
    horizontal = [w for w in wings if w.horizontal]
    crossing = [w for w in wings if not w.horizontal]

    def end_room(across: int) -> int:
        """How far a corridor stops short of its wing's end: at the outer wall, or before a room
        across the wing's end (at least 1 / 2.4 of the wing's depth across it, so that it is no
        corridor-like sliver that would need rooms behind rooms)."""
        if not drawing.chance(config.end_room_chance):
            return outer
        return outer + max(drawing.draw(config.room_depth_m), int(across / 2.4)) + wall

    for w in horizontal:
        top, left, bottom, right = w.rect
        start, stop = left + end_room(bottom - top), right - end_room(bottom - top)
        for c in crossing:
            c_top, c_left, c_bottom, c_right = c.rect
            if not (c_top <= top and c_bottom >= bottom and left <= c_left < right):
                continue
            offset, width = c.spans[0]
            start = c_left + offset if c_left == left else min(start, c_left + offset)
            stop = c_left + offset + width if c_right == right else max(stop, c_left + offset + width)
        w.corridors = [(top + offset, start, top + offset + width, stop) for offset, width in w.spans]
        w.caps = ([start - wall] if start > left + outer else []) + ([stop] if stop < right - outer else [])
        if len(w.spans) == 2:  # a deep block: links across its core join its two corridors
            (first, _), (second, second_width) = w.spans
            link = drawing.draw_opening(config.corridor_m)
            for _ in range(1 + int(stop - start > config.cells(40.0))):
                at = int(drawing.rng.integers(start, max(start + 1, stop - link + 1)))
                w.corridors.append((top + first, at, top + second + second_width, at + link))
    for c in crossing:
        c_top, c_left, c_bottom, c_right = c.rect
        offset, width = c.spans[0]
        met = [w for w in horizontal
               if c_top <= w.rect[0] and c_bottom >= w.rect[2] and w.rect[1] <= c_left < w.rect[3]]
        rows = [row for w in met for corridor in w.corridors for row in (corridor[0], corridor[2])]
        if not rows:
            continue
        above, below = c_top < min(w.rect[0] for w in met), c_bottom > max(w.rect[2] for w in met)
        start = c_top + end_room(c_right - c_left) if above else min(rows)
        stop = c_bottom - end_room(c_right - c_left) if below else max(rows)
        c.corridors = [(start, c_left + offset, stop, c_left + offset + width)]
        c.caps = (([start - wall] if above and start > c_top + outer else [])
                  + ([stop] if below and stop < c_bottom - outer else []))


def _outline(drawing: _Drawing, wings: list[_Wing], outer: int) -> None:
    """The floor's inside: the union of the wings with bays added and recesses and perhaps one
    cut corner taken out (never across a corridor), free, with the outer wall ring along it."""
    config, rng, n = drawing.config, drawing.rng, drawing.n
    inside = np.zeros((n, n), dtype=bool)
    for w in wings:
        inside[w.rect[0] : w.rect[2], w.rect[1] : w.rect[3]] = True
    corridor = np.zeros((n, n), dtype=bool)
    for w in wings:
        for top, left, bottom, right in w.corridors:
            corridor[top:bottom, left:right] = True
    keep = cv2.dilate(corridor.astype(np.uint8), np.ones((2 * outer + 3,) * 2, np.uint8)).astype(bool)

    def outline_cell() -> tuple[int, int, int, int] | None:
        """(row, col, dr, dc): an inside cell drawn at random whose neighbour (dr, dc) is outside, the
        direction drawn first; None when no cell of the outline faces that way."""
        padded = np.pad(inside, 1)
        dr, dc = ((-1, 0), (1, 0), (0, -1), (0, 1))[int(rng.integers(4))]
        cells = np.argwhere(inside & ~padded[1 + dr : n + 1 + dr, 1 + dc : n + 1 + dc])
        if not len(cells):
            return None
        row, col = cells[int(rng.integers(len(cells)))]
        return row, col, dr, dc

    for _ in range(int(rng.integers(config.bays[0], config.bays[1] + 1))):
        picked = outline_cell()
        if picked is None:
            continue
        row, col, dr, dc = picked
        along, out = drawing.draw(config.bay_m), drawing.draw(config.bay_m)
        if dr:
            top = row + 1 if dr > 0 else row - out
            rect = (top, col - along // 2, top + out, col + along - along // 2)
        else:
            left = col + 1 if dc > 0 else col - out
            rect = (row - along // 2, left, row + along - along // 2, left + out)
        top, left, bottom, right = rect
        if top >= 1 and left >= 1 and bottom <= n - 1 and right <= n - 1:
            inside[top:bottom, left:right] = True
    for _ in range(int(rng.integers(config.recesses[0], config.recesses[1] + 1))):
        picked = outline_cell()
        if picked is None:
            continue
        row, col, dr, dc = picked
        along, depth = drawing.draw((2.0, 8.0)), drawing.draw(config.recess_m) + outer
        if dr:
            top = row - depth + 1 if dr > 0 else row
            rect = (top, col - along // 2, top + depth, col + along - along // 2)
        else:
            left = col - depth + 1 if dc > 0 else col
            rect = (row - along // 2, left, row + along - along // 2, left + depth)
        top, left, bottom, right = (max(0, v) for v in rect)
        if not keep[top:bottom, left:right].any():
            inside[top:bottom, left:right] = False
    if drawing.chance(config.chamfer_chance):
        rows, cols = np.nonzero(inside)
        top, left, bottom, right = rows.min(), cols.min(), rows.max() + 1, cols.max() + 1
        size = int(min(bottom - top, right - left) * rng.uniform(0.15, 0.35))
        corner = int(rng.integers(4))
        r, c = np.indices((n, n))
        r = r - top if corner < 2 else bottom - 1 - r
        c = c - left if corner % 2 == 0 else right - 1 - c
        cut = (r + c < size) & inside
        if not (cut & keep).any():
            inside &= ~cut
    drawing.labels[inside] = FREE_LABEL
    outside = (~inside).astype(np.uint8)
    ring = cv2.dilate(outside, np.ones((2 * outer + 1,) * 2, np.uint8)).astype(bool) & inside
    drawing.labels[ring] = WALL_LABEL


# ---------------------------------------------------------------------------- rooms
def _rooms(drawing: _Drawing, wings: list[_Wing]) -> None:
    """Corridors and their walls, then each wing's strips beside its corridors cut into rooms
    (regions 1, 2, ...); a later wing is walled off from what an earlier one claimed."""
    labels, region, n = drawing.labels, drawing.region, drawing.n
    corridor = np.zeros((n, n), dtype=bool)
    for w in wings:
        for top, left, bottom, right in w.corridors:
            corridor[top:bottom, left:right] = True
    corridor &= labels == FREE_LABEL
    region[corridor] = CORRIDOR
    wall = drawing.corridor_wall
    walls = cv2.dilate(corridor.astype(np.uint8), np.ones((2 * wall + 1,) * 2, np.uint8)).astype(bool) & ~corridor
    for w in wings:  # the corridor walls as runs, for the record
        for top, left, bottom, right in w.corridors:
            for rect in ((top - wall, left - wall, top, right + wall),
                         (bottom, left - wall, bottom + wall, right + wall),
                         (top, left - wall, bottom, left), (top, right, bottom, right + wall)):
                drawing.wall(rect, walls)
    claimed = np.zeros((n, n), dtype=bool)
    next_id = 1
    for w in wings:
        top, left, bottom, right = w.rect
        mine = np.zeros((n, n), dtype=bool)
        mine[top:bottom, left:right] = True
        mine &= (labels == FREE_LABEL) & (region == 0) & ~claimed
        # A wall where this wing meets cells an earlier wing claimed.
        border = cv2.dilate(claimed.astype(np.uint8), np.ones((2 * wall + 1,) * 2, np.uint8)).astype(bool) & mine
        labels[border] = WALL_LABEL
        mine &= ~border
        claimed |= mine
        count, pieces = cv2.connectedComponents(mine.astype(np.uint8), connectivity=4)
        for piece in range(1, count):
            next_id = _cut_strip(drawing, pieces == piece, w.horizontal, w.caps, next_id)
    # Cells no wing claimed (bays; the corridors' walls keep them off the corridors): part of the
    # room they open onto, or, walled off all round, a room of their own with a door like any other.
    leftover = (labels == FREE_LABEL) & (region == 0)
    count, parts = cv2.connectedComponents(leftover.astype(np.uint8), connectivity=4)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    for part in range(1, count):
        mask = parts == part
        neighbours = region[cv2.dilate(mask.astype(np.uint8), cross).astype(bool) & ~mask]
        rooms, votes = np.unique(neighbours[neighbours > 0], return_counts=True)
        if len(rooms):
            region[mask] = rooms[int(np.argmax(votes))]
        else:
            region[mask] = next_id
            next_id += 1
    _drop_slivers(drawing)


def _cut_strip(drawing: _Drawing, piece: np.ndarray, horizontal: bool, caps: list[int], next_id: int,
               turned: bool = False) -> int:
    """Cut one strip into rooms by cross walls across it (at its forced `caps`, and at room
    widths drawn one after another along it: a strip of a `horizontal` wing runs along the rows).
    A room that comes out much deeper than wide (the room across a wing's end, beyond its
    corridor) is cut again the other way (`turned`); a deep room may be split into a front room
    and a back room. Returns the next free room id."""
    config, labels, region = drawing.config, drawing.labels, drawing.region
    rows, cols = np.nonzero(piece)
    axis = cols if horizontal else rows
    low, high = int(axis.min()), int(axis.max()) + 1
    min_width = config.cells(config.room_width_m[0])
    forced = sorted(c for c in caps if low + min_width <= c <= high - min_width)
    cuts = [(c, drawing.corridor_wall) for c in forced]  # (position, thickness) along the strip
    for start, end in zip([low] + [c + drawing.corridor_wall for c in forced], forced + [high]):
        position = start
        while True:
            if drawing.chance(config.hall_chance):
                width = drawing.draw(config.hall_m)
            elif drawing.chance(config.large_room_chance):
                width = drawing.draw(config.large_room_m)
            else:
                width = drawing.draw(config.room_width_m)
            thickness = drawing.draw_wall(config.wall_m)
            if end - (position + width + thickness) < min_width:
                break
            cuts.append((position + width, thickness))
            position += width + thickness
    for position, thickness in cuts:
        if horizontal:
            rect = (int(rows.min()), position, int(rows.max()) + 1, position + thickness)
        else:
            rect = (position, int(cols.min()), position + thickness, int(cols.max()) + 1)
        block = (slice(rect[0], rect[2]), slice(rect[1], rect[3]))
        cells = piece[block] & (labels[block] == FREE_LABEL)
        labels[block][cells] = WALL_LABEL
        if cells.any():
            drawing.walls.append(rect)
    count, parts = cv2.connectedComponents((piece & (labels == FREE_LABEL)).astype(np.uint8), connectivity=4)
    for part in range(1, count):
        mask = parts == part
        part_rows, part_cols = np.nonzero(mask)
        along = np.ptp(part_cols if horizontal else part_rows) + 1
        across = np.ptp(part_rows if horizontal else part_cols) + 1
        if not turned and across >= 2.5 * along and across >= 2 * min_width + drawing.wall_cells:
            next_id = _cut_strip(drawing, mask, not horizontal, [], next_id, turned=True)
            continue
        region[mask] = next_id
        next_id = _split_deep_room(drawing, mask, horizontal, next_id + 1)
    return next_id


def _split_deep_room(drawing: _Drawing, mask: np.ndarray, horizontal: bool, next_id: int) -> int:
    """Perhaps split a room deep enough for two along its strip (`horizontal`: along the rows)
    into two rooms, one behind the other: one that keeps no corridor wall is reached through the
    other (`_doors`). Returns the next free room id."""
    config, rng, labels, region = drawing.config, drawing.rng, drawing.labels, drawing.region
    rows, cols = np.nonzero(mask)
    across = rows if horizontal else cols
    along = cols if horizontal else rows
    depth = int(across.max()) - int(across.min()) + 1
    width = int(along.max()) - int(along.min()) + 1
    least = config.cells(max(2.4, 2 * config.door_m[1]))
    if depth < 2 * least + drawing.wall_cells or width > config.cells(config.large_room_m[0]):
        return next_id
    if not drawing.chance(config.back_room_chance):
        return next_id
    thickness = drawing.draw_wall(config.wall_m)
    cut = int(rng.integers(int(across.min()) + least, int(across.max()) + 1 - least - thickness + 1))
    if horizontal:
        rect = (cut, int(cols.min()), cut + thickness, int(cols.max()) + 1)
    else:
        rect = (int(rows.min()), cut, int(rows.max()) + 1, cut + thickness)
    block = (slice(rect[0], rect[2]), slice(rect[1], rect[3]))
    cells = mask[block]
    labels[block][cells] = WALL_LABEL
    region[block][cells] = 0
    drawing.walls.append(rect)
    beyond = across >= cut + thickness
    region[rows[beyond], cols[beyond]] = next_id
    return next_id + 1


def _drop_slivers(drawing: _Drawing) -> None:
    """Rooms too small or too narrow for a door and a robot (left where wings meet) become solid."""
    config, labels, region = drawing.config, drawing.labels, drawing.region
    least = config.cells(config.door_m[1]) + 2
    for room, box in _room_boxes(region).items():
        crop = _crop(box)
        mask = region[crop] == room
        if min(box[2] - box[0], box[3] - box[1]) < least or mask.sum() < least * least:
            labels[crop][mask], region[crop][mask] = WALL_LABEL, 0


# ---------------------------------------------------------------------------- doors
def _door_places(drawing: _Drawing, room: int, goal: np.ndarray, width: int) -> list[Rect]:
    """Every place a door `width` cells wide fits through a straight wall (1 to wall_cells + 1
    cells thick) between room `room` and a region `goal` holds (`goal[region + 1]`: CORRIDOR at
    0), with wall beyond both of its ends on its line (so it stops short of a corner and of
    another door)."""
    region, labels = drawing.region, drawing.labels
    pad = drawing.wall_cells + 2
    box = drawing.boxes[room]
    top, left = max(0, box[0] - pad), max(0, box[1] - pad)
    bottom, right = min(drawing.n, box[2] + pad), min(drawing.n, box[3] + pad)
    near_region = region[top:bottom, left:right]
    own = near_region == room
    wall = (labels[top:bottom, left:right] == WALL_LABEL) & (near_region == 0)
    target = goal[near_region + 1] & (labels[top:bottom, left:right] == FREE_LABEL) & ~own & (near_region != 0)
    places: list[Rect] = []
    for transposed in (False, True):  # doors through walls along the rows, then along the columns
        a_own, a_wall, a_goal = (own.T, wall.T, target.T) if transposed else (own, wall, target)
        height, length = a_own.shape
        if length < width + 2:
            continue
        for k in range(1, drawing.wall_cells + 2):
            if height < k + 2:
                continue
            # through[r, c]: cells r + 1 .. r + k of column c are wall.
            through = np.ones((height - k - 1, length), dtype=bool)
            for j in range(1, k + 1):
                through &= a_wall[j : height - k - 1 + j]
            if not through.any():
                continue
            ends = through[:, : -width - 1] & through[:, width + 1 :]
            for near, far in ((a_own, a_goal), (a_goal, a_own)):
                crossing = near[: height - k - 1] & far[k + 1 :] & through
                if not crossing.any():
                    continue
                sums = np.zeros((crossing.shape[0], length + 1), dtype=np.int32)
                np.cumsum(crossing, axis=1, out=sums[:, 1:])
                fits = (sums[:, width + 1 : -1] - sums[:, 1 : -width - 1]) == width
                for r, c in np.argwhere(fits & ends):
                    a, b = r + 1, c + 1  # the door's first wall cell across, its first cell along
                    if transposed:
                        places.append((top + b, left + a, top + b + width, left + a + k))
                    else:
                        places.append((top + a, left + b, top + a + k, left + b + width))
    return places


def _open_door(drawing: _Drawing, room: int, goal: np.ndarray, width: int | None = None) -> bool:
    """Open a door from `room` into a region `goal` holds (see `_door_places`) at one of its
    places, of a width drawn from `door_m` (the narrowest where that fits nowhere); False when no
    door fits."""
    width = width if width is not None else drawing.draw_opening(drawing.config.door_m)
    places = _door_places(drawing, room, goal, width)
    if not places:
        smallest = max(2, int(math.floor(drawing.config.door_m[0] / drawing.config.cell_size - 0.5)))
        return _open_door(drawing, room, goal, smallest) if width > smallest else False
    top, left, bottom, right = places[int(drawing.rng.integers(len(places)))]
    drawing.labels[top:bottom, left:right] = FREE_LABEL
    drawing.region[top:bottom, left:right] = 0
    drawing.doors.append((top, left, bottom, right))
    return True


def _doors(drawing: _Drawing) -> None:
    """One door per room onto a corridor where it has a corridor wall; rooms without one open
    into a neighbouring room that is reached already; then second doors (more for large rooms,
    mostly onto a corridor); a few rooms open onto their corridor over their whole side instead
    (lobbies)."""
    config, region = drawing.config, drawing.region
    drawing.boxes = _room_boxes(region)
    ids = sorted(drawing.boxes)
    order = [ids[i] for i in drawing.rng.permutation(len(ids))]
    slots = max(ids, default=0) + 2  # lookups per region id + 1: CORRIDOR at 0, wall at 1
    corridor = np.zeros(slots, dtype=bool)
    corridor[0] = True
    rooms = np.ones(slots, dtype=bool)
    rooms[:2] = False
    reached = corridor.copy()
    cell_m2 = config.cell_size**2
    area = {room: float((region[_crop(drawing.boxes[room])] == room).sum()) * cell_m2 for room in ids}
    for room in order:
        if area[room] <= config.large_room_m2 and drawing.chance(config.open_room_chance) and _open_room(drawing, room):
            continue
        reached[room + 1] = _open_door(drawing, room, corridor)
    waiting = [room for room in order if not reached[room + 1] and (region[_crop(drawing.boxes[room])] == room).any()]
    while waiting:
        opened = [room for room in waiting if _open_door(drawing, room, reached)]
        reached[[room + 1 for room in opened]] = True
        waiting = [room for room in waiting if room not in opened]
        if not opened:
            break
    for room in waiting:  # no wall it shares with anything reached: locked, solid
        crop = _crop(drawing.boxes[room])
        mask = region[crop] == room
        drawing.labels[crop][mask], region[crop][mask] = WALL_LABEL, 0
    for room in order:
        if not reached[room + 1] or not (region[_crop(drawing.boxes[room])] == room).any():
            continue
        extra = 0
        if area[room] > config.large_room_m2:
            extra = int(drawing.chance(config.large_door_chance)) + int(drawing.chance(config.large_door_chance / 4))
        elif drawing.chance(config.second_door_chance):
            extra = 1
        others = rooms.copy()
        others[room + 1] = False
        for _ in range(extra):
            if not _open_door(drawing, room, corridor if drawing.chance(0.75) else others):
                _open_door(drawing, room, corridor | others)


def _open_room(drawing: _Drawing, room: int) -> bool:
    """Open `room` onto a corridor over the longest wall it shares with one and make it corridor
    (a lobby: free space that is no room); False (nothing changed) when it shares none."""
    corridor = np.zeros(int(drawing.region.max()) + 2, dtype=bool)
    corridor[0] = True
    places: list[Rect] = []
    for width in range(drawing.config.cells(8.0), drawing.config.cells(drawing.config.door_m[1]), -2):
        places = _door_places(drawing, room, corridor, width)
        if places:
            break
    if not places:
        return False
    top, left, bottom, right = places[int(drawing.rng.integers(len(places)))]
    drawing.labels[top:bottom, left:right] = FREE_LABEL
    drawing.region[top:bottom, left:right] = CORRIDOR
    crop = _crop(drawing.boxes[room])
    drawing.region[crop][drawing.region[crop] == room] = CORRIDOR
    drawing.doors.append((top, left, bottom, right))
    return True


# ---------------------------------------------------------------------------- furniture
def _furnish(drawing: _Drawing) -> None:
    """Tables, shelves along walls, partial walls in large rooms and (in halls) a row of columns,
    kept clear of the doors; a piece that would cut its room in two is not placed."""
    config, rng, labels, region = drawing.config, drawing.rng, drawing.labels, drawing.region
    n = drawing.n
    keep_clear = np.zeros((n, n), dtype=bool)
    clearance = config.cells(config.door_clearance_m)
    for top, left, bottom, right in drawing.doors:
        keep_clear[max(0, top - clearance) : min(n, bottom + clearance),
                   max(0, left - clearance) : min(n, right + clearance)] = True
    for room, (top, left, bottom, right) in _room_boxes(region).items():
        crop = (slice(top, bottom), slice(left, right))
        mask = np.zeros((n, n), dtype=bool)
        mask[crop] = region[crop] == room
        rows, cols = np.nonzero(mask[crop])
        rows, cols = rows + top, cols + left
        height, width = bottom - top, right - left

        def place(r0: int, c0: int, h: int, w: int, label: int = FURNITURE_LABEL) -> None:
            block = (slice(r0, r0 + h), slice(c0, c0 + w))
            if h <= 0 or w <= 0 or r0 < top or c0 < left or r0 + h > bottom or c0 + w > right:
                return
            if not (mask[block].all() and (labels[block] == FREE_LABEL).all()) or keep_clear[block].any():
                return
            labels[block] = label
            room_free = mask[crop] & (labels[crop] == FREE_LABEL)
            if cv2.connectedComponents(room_free.astype(np.uint8), connectivity=4)[0] > 2:
                labels[block] = FREE_LABEL  # it would cut the room in two

        for _ in range(int(rng.integers(config.furniture[0], config.furniture[1] + 1))):
            if drawing.chance(0.45):  # a table, away from the walls
                h, w = drawing.draw(config.table_m), drawing.draw(config.table_m)
                if height - h > 6 and width - w > 6:
                    place(int(rng.integers(top + 3, bottom - h - 2)), int(rng.integers(left + 3, right - w - 2)), h, w)
            else:  # a shelf along one of the room's walls
                depth, length = drawing.draw(config.shelf_m), drawing.draw((1.0, 3.0))
                side = int(rng.integers(4))
                if side < 2 and width > length + 2:
                    col = int(rng.integers(left, right - length))
                    span = rows[cols == col]
                    if len(span):
                        row = int(span.min()) if side == 0 else int(span.max()) + 1 - depth
                        place(row, col, depth, length)
                elif side >= 2 and height > length + 2:
                    row = int(rng.integers(top, bottom - length))
                    span = cols[rows == row]
                    if len(span):
                        col = int(span.min()) if side == 2 else int(span.max()) + 1 - depth
                        place(row, col, length, depth)
        area = float(mask.sum()) * config.cell_size**2
        if area > config.large_room_m2 and drawing.chance(config.stub_chance):  # a partial wall
            thickness = drawing.draw_wall(config.wall_m)
            if height >= width:
                row = int(rng.integers(top + height // 3, bottom - height // 3))
                reach = int(width * rng.uniform(0.3, 0.6))
                place(row, left if drawing.chance(0.5) else right - reach, thickness, reach, WALL_LABEL)
            else:
                col = int(rng.integers(left + width // 3, right - width // 3))
                reach = int(height * rng.uniform(0.3, 0.6))
                place(top if drawing.chance(0.5) else bottom - reach, col, reach, thickness, WALL_LABEL)
        if min(height, width) > config.cells(8.0):  # a hall: a row of columns down its middle
            size = drawing.draw(config.column_m)
            spacing = config.cells(float(rng.uniform(3.0, 5.0)))
            if height >= width:
                for row in range(top + spacing, bottom - spacing, spacing):
                    place(row, (left + right) // 2, size, size)
            else:
                for col in range(left + spacing, right - spacing, spacing):
                    place((top + bottom) // 2, col, size, size)


# ---------------------------------------------------------------------------- start and reach
def _pick_start(drawing: _Drawing) -> tuple[int, int]:
    """A start cell with free cells all round its START_CELLS square."""
    free = drawing.labels == FREE_LABEL
    clear = cv2.erode(free.astype(np.uint8), np.ones((2 * START_CELLS + 1,) * 2, np.uint8)).astype(bool)
    candidates = np.argwhere(clear)
    if not len(candidates):
        raise RuntimeError("building generator bug: no free cell has room for the start")
    row, col = candidates[int(drawing.rng.integers(len(candidates)))]
    return int(row), int(col)


def _close_unreachable(drawing: _Drawing, start: tuple[int, int]) -> float:
    """Free space a robot of `robot_radius_m` cannot reach from the start leaves the floor
    (solid on the map, outside in the labels, no room); the share of the free space closed."""
    config, labels = drawing.config, drawing.labels
    free = labels == FREE_LABEL
    reached = reachable_free(free, (start[1], start[0]), config.robot_radius_m / config.cell_size)
    closed = free & ~reached
    labels[closed] = OUTSIDE_LABEL
    drawing.region[closed] = 0
    return float(closed.sum()) / max(1, int(free.sum()))


MAX_CLOSED_SHARE = 0.1  # a floor that loses more of its free space to unreachable parts is drawn again
DRAW_ATTEMPTS = 10


def _room_record(drawing: _Drawing) -> tuple[np.ndarray, tuple[Rect, ...]]:
    """Room labels 1..N (renumbered in order, free cells only) and each room's bounding rectangle."""
    region = np.where(drawing.labels == FREE_LABEL, drawing.region, 0)
    ids = np.unique(region[region > 0])
    lookup = np.zeros(int(region.max()) + 1 if region.size else 1, dtype=np.int32)
    lookup[ids] = np.arange(1, len(ids) + 1, dtype=np.int32)
    labels = np.where(region > 0, lookup[np.maximum(region, 0)], 0).astype(np.int32)
    rects = []
    for room in range(1, len(ids) + 1):
        rows, cols = np.nonzero(labels == room)
        rects.append((int(rows.min()), int(cols.min()), int(rows.max()) + 1, int(cols.max()) + 1))
    return labels, tuple(rects)


def draw_building(config: BuildingConfig, rng: np.random.Generator) -> BuildingFloor:
    """One building floor: labels (free, wall, furniture, outside), start, lattice, rooms, doors.

    A floor whose unreachable parts (`_close_unreachable`) take more than MAX_CLOSED_SHARE of its
    free space is drawn again from the same random source (at most DRAW_ATTEMPTS times), so that
    a floor's size is about its side's."""
    for _ in range(DRAW_ATTEMPTS):
        drawing = _Drawing(config, rng)
        outer = drawing.draw_wall(config.outer_wall_m)
        drawing.corridor_wall = drawing.draw_wall(config.wall_m)
        wings = _layout(drawing, outer)
        _outline(drawing, wings, outer)
        _rooms(drawing, wings)
        _doors(drawing)
        _furnish(drawing)
        start = _pick_start(drawing)
        if _close_unreachable(drawing, start) <= MAX_CLOSED_SHARE:
            break
    room_labels, rooms = _room_record(drawing)
    phase = (start[0] % drawing.step, start[1] % drawing.step)
    return BuildingFloor(drawing.labels, start, drawing.step, phase, rooms, tuple(drawing.doors),
                         tuple(drawing.walls), room_labels)


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
    """A floor's shape as `plan_statistics` measures real plans (from its free cells and its own
    room record), and two things only a drawn floor knows, at its lattice:

    - `wall_runs_on_nodes`: the share of interior wall runs (as drawn) that cover a lattice node;
    - `nodes_on_furniture`: the share of the lattice nodes inside the outline on furniture.
    """
    labels, step, (row_phase, col_phase) = floor.labels, floor.step, floor.phase
    nodes = labels[row_phase::step, col_phase::step]
    inside = nodes != OUTSIDE_LABEL
    node_grid = np.zeros(labels.shape, dtype=bool)
    node_grid[row_phase::step, col_phase::step] = True
    on_nodes = [node_grid[top:bottom, left:right].any() for top, left, bottom, right in floor.walls]
    out = plan_statistics(floor.free, floor.room_labels, cell_size)
    out["wall_runs_on_nodes"] = float(np.mean(on_nodes)) if on_nodes else 0.0
    out["nodes_on_furniture"] = float((nodes[inside] == FURNITURE_LABEL).mean()) if inside.any() else 0.0
    return out
