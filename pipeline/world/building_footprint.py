"""A building floor's footprint: wings joined into a shape, their corridors and the outer wall,
drawn on a Drawing (the state of one floor being drawn).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from pipeline.world.building_config import FREE_LABEL, OUTSIDE_LABEL, SHAPES, WALL_LABEL, BuildingConfig, Rect


@dataclass
class Wing:
    """One wing of the footprint: its rectangle, whether it runs along the rows (a horizontal
    wing, its corridor along its length), its profile across (each corridor's offset and width
    from the wing's near side), and then its corridor rectangles and the positions along it where
    a cross wall is forced (where a corridor ends inside the wing: the end room's wall)."""

    rect: Rect
    horizontal: bool
    spans: list[tuple[int, int]]
    corridors: list[Rect] = field(default_factory=list)
    caps: list[int] = field(default_factory=list)


class Drawing:
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


def room_boxes(region: np.ndarray) -> dict[int, Rect]:
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
    return {
        int(ids[s]): (int(top), int(left), int(bottom), int(right))
        for s, top, left, bottom, right in zip(starts, tops, lefts, bottoms, rights)
    }


def rect_slices(box: Rect) -> tuple[slice, slice]:
    """The slices of a rectangle."""
    return slice(box[0], box[2]), slice(box[1], box[3])


def _wing_profile(drawing: Drawing, outer: int, wall: int, deep: bool = False) -> tuple[int, list[tuple[int, int]]]:
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


def layout_wings(drawing: Drawing, outer: int) -> list[Wing]:
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
        return _placed(drawing, [Wing((0, 0, depth, length), True, across)], outer)
    height = min(max(int(length / rng.uniform(*config.aspect)), needed), span)
    min_fill = rng.uniform(*config.min_fill)
    reach_share = [
        rng.uniform(0.5, 1.0) if shape in ("L", "U", "E", "T") and drawing.chance(0.4) else 1.0 for _ in range(3)
    ]  # arms of unequal length
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
        wings = [Wing((top, 0, top + depth, length), True, across)]
        if shape == "ring":
            wings.append(Wing((height - widths[3], 0, height, length), True, cross[3][1]))
        for k, x in enumerate(positions):
            reach = max(top + depth + margin, int(height * reach_share[k]))
            wings.append(Wing((0, x, reach, x + widths[k]), False, cross[k][1]))
        cover = np.zeros((height, length), dtype=bool)
        for w in wings:
            cover[w.rect[0] : w.rect[2], w.rect[1] : w.rect[3]] = True
        if cover.mean() >= min_fill or height <= needed:
            break
        height = max(needed, int(height * 0.9))
    return _placed(drawing, wings, outer)


def _placed(drawing: Drawing, wings: list[Wing], outer: int) -> list[Wing]:
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


def _corridors(drawing: Drawing, wings: list[Wing], outer: int) -> None:
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
        met = [
            w for w in horizontal if c_top <= w.rect[0] and c_bottom >= w.rect[2] and w.rect[1] <= c_left < w.rect[3]
        ]
        rows = [row for w in met for corridor in w.corridors for row in (corridor[0], corridor[2])]
        if not rows:
            continue
        above, below = c_top < min(w.rect[0] for w in met), c_bottom > max(w.rect[2] for w in met)
        start = c_top + end_room(c_right - c_left) if above else min(rows)
        stop = c_bottom - end_room(c_right - c_left) if below else max(rows)
        c.corridors = [(start, c_left + offset, stop, c_left + offset + width)]
        c.caps = ([start - wall] if above and start > c_top + outer else []) + (
            [stop] if below and stop < c_bottom - outer else []
        )


def draw_outline(drawing: Drawing, wings: list[Wing], outer: int) -> None:
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
