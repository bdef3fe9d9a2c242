"""The shape of a floor, measured the same way on real plans and on generated building floors.

A generated map family teaches an inpainter what unknown space looks like, so the family should
have the real plans' proportions: how much of its bounding box a floor fills and how elongated
that box is, how many rooms it has and how large, how rooms open (one door, or several), how
much of the floor is corridor rather than room, how often a 1 m lattice node lands on a wall,
and how wide doors are. `plan_statistics` measures all of these on a free grid with room labels
(0 = no room, 1..N = a room) at the protocol's 0.2 m cells; `real_plan_grids` brings a folder
of labelled plans (data/real_plans/kth/) to those cells by the rule the plan import uses
(`pipeline.world.plans.convert_plan`: conservative, but keeping every door a 0.2 m-radius robot
fits through, largest component) and their labels by block mode.

A *door* of a room is a connected opening from the room to anything else that is free: another
room or free space that is no room (a corridor, a hall). It is found as the free cells outside
the room that touch it (4-neighbours), grouped into 8-connected parts; a part is one door, its
width the longer side of its bounding box. An opening narrower than `MIN_DOOR_M` (a label's
ragged edge touching a corridor across one cell) is no door.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import cast

import cv2
import numpy as np

from pipeline.world.plans import convert_plan, find_plan_sources

STAT_CELL_M = 0.2  # the cells every statistic is measured at
MIN_ROOM_M2 = 1.0  # a labelled region smaller than this (a label's sliver) is no room
MIN_DOOR_M = 0.4  # an opening narrower than the robot's diameter is no door
FOOTPRINT_CLOSE_M = 1.0  # walls and furniture thinner than this between free cells are inside the footprint,
FOOTPRINT_HOLE_M2 = 25.0  # and so is an enclosed non-free region smaller than this (furniture, a shaft)
CORRIDOR_WIDTH_M = 3.5  # a region at most this wide ...
CORRIDOR_ELONGATION = 5.0  # ... and at least this many times as long is a corridor, labelled or not

STATISTICS = {  # name: what it is, as a table row says it
    "free_share": "free share of the free area's bounding box",
    "aspect": "bounding box: long side / short side",
    "rooms_per_100m2": "rooms per 100 m^2 of free area",
    "room_m2": "median room area (m^2)",
    "doors_per_room": "doors per room (mean)",
    "one_door_share": "share of rooms with exactly one door",
    "corridor_share": "corridor share (free cells in no room)",
    "nodes_on_walls": "1 m lattice nodes inside the footprint on walls or furniture",
    "door_m": "median door width (m)",
    "free_m2": "free area (m^2)",
}


def plan_statistics(free: np.ndarray, rooms: np.ndarray | None, cell_size: float) -> dict[str, float]:
    """The floor-shape statistics (STATISTICS names them) of one floor at `cell_size` cells.

    `free` is the floor's free grid, `rooms` its room labels (same shape; 0 = no room, 1..N = a
    room; only free cells count). A room is a label of at least MIN_ROOM_M2 that is no corridor
    (`is_corridor`): real plans label their corridors as rooms. Without labels, the room, door
    and corridor statistics are NaN. `nodes_on_walls` is the share of 1 m lattice nodes inside
    the footprint (`footprint`) that are not free, averaged over every phase of the lattice on the
    grid (a real plan has no phase of its own): the non-free share of the footprint's cells.
    """
    free = np.asarray(free, dtype=bool)
    nan = float("nan")
    out = {key: nan for key in STATISTICS}
    if not free.any():
        return out
    rows, cols = np.nonzero(free)
    height, width = rows.max() - rows.min() + 1, cols.max() - cols.min() + 1
    out["free_share"] = float(free.sum()) / float(height * width)
    out["aspect"] = float(max(height, width)) / float(min(height, width))
    free_m2 = float(free.sum()) * cell_size**2
    out["free_m2"] = free_m2
    inside = footprint(free, cell_size)
    out["nodes_on_walls"] = float((inside & ~free).sum()) / float(max(1, inside.sum()))
    if rooms is None:
        return out
    labels = np.where(free, np.asarray(rooms), 0)
    ids, counts = np.unique(labels[labels > 0], return_counts=True)
    is_room = np.array(
        [
            count * cell_size**2 >= MIN_ROOM_M2 and not is_corridor(labels == room, cell_size)
            for room, count in zip(ids, counts)
        ],
        dtype=bool,
    )
    kept, areas = ids[is_room], counts[is_room] * cell_size**2
    out["corridor_share"] = 1.0 - float(np.isin(labels, kept).sum()) / float(free.sum())
    if not len(kept):
        return out
    out["rooms_per_100m2"] = 100.0 * len(kept) / free_m2
    out["room_m2"] = float(np.median(areas))
    doors = [room_doors(labels, free, int(room), cell_size) for room in kept]
    counts_per_room = np.array([len(d) for d in doors])
    widths = [w for d in doors for w in d]
    out["doors_per_room"] = float(counts_per_room.mean())
    out["one_door_share"] = float((counts_per_room == 1).mean())
    out["door_m"] = float(np.median(widths)) if widths else nan
    return out


def is_corridor(mask: np.ndarray, cell_size: float) -> bool:
    """Whether a region is a corridor: with its holes (furniture inside a room) filled, at most
    CORRIDOR_WIDTH_M wide (twice its largest distance from its edge) and at least
    CORRIDOR_ELONGATION times as long as wide (its area over its width). Real plans label
    corridors as rooms; this finds them there and on generated floors alike."""
    rows, cols = np.nonzero(mask)
    crop = np.pad(mask[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1], 1)
    _, parts = cv2.connectedComponents((~crop).astype(np.uint8), connectivity=4)
    filled = crop | (parts != parts[0, 0])
    width = 2.0 * float(cv2.distanceTransform(filled.astype(np.uint8), cv2.DIST_L2, 5).max()) * cell_size
    length = float(filled.sum()) * cell_size**2 / width
    return bool(width <= CORRIDOR_WIDTH_M and length >= CORRIDOR_ELONGATION * width)


def room_doors(labels: np.ndarray, free: np.ndarray, room: int, cell_size: float) -> list[float]:
    """The widths (m) of the doors of room `room` (the module doc says what a door is)."""
    mask = labels == room
    rows, cols = np.nonzero(mask)
    top, left = max(0, rows.min() - 2), max(0, cols.min() - 2)
    bottom, right = min(mask.shape[0], rows.max() + 3), min(mask.shape[1], cols.max() + 3)
    own = mask[top:bottom, left:right].astype(np.uint8)
    cross = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))
    contact = cv2.dilate(own, cross).astype(bool) & free[top:bottom, left:right] & ~own.astype(bool)
    count, _, stats, _ = cv2.connectedComponentsWithStats(contact.astype(np.uint8), connectivity=8)
    widths = np.maximum(stats[1:, cv2.CC_STAT_WIDTH], stats[1:, cv2.CC_STAT_HEIGHT]) * cell_size
    return [float(w) for w in widths if w >= MIN_DOOR_M - 1e-9]


def footprint(free: np.ndarray, cell_size: float) -> np.ndarray:
    """The cells inside the building: free cells, the walls and furniture between them (gaps
    thinner than FOOTPRINT_CLOSE_M) and enclosed non-free regions smaller than FOOTPRINT_HOLE_M2
    (a courtyard or the outside stays out)."""
    size = max(1, int(round(FOOTPRINT_CLOSE_M / cell_size)))
    kernel = np.ones((size, size), np.uint8)
    closed = cv2.morphologyEx(np.pad(free, size).astype(np.uint8), cv2.MORPH_CLOSE, kernel)[size:-size, size:-size]
    closed = closed.astype(bool) | free
    around = np.pad(~cast(np.ndarray, closed), 1, constant_values=True).astype(np.uint8)  # the outside joined all round
    count, parts, stats, _ = cv2.connectedComponentsWithStats(around, connectivity=4)
    small = np.zeros(count, dtype=bool)
    small[1:] = stats[1:, cv2.CC_STAT_AREA] * cell_size**2 < FOOTPRINT_HOLE_M2
    small[parts[0, 0]] = False  # the region around the grid is the outside, whatever its size
    return closed | small[parts[1:-1, 1:-1]]


def block_mode_labels(labels: np.ndarray, free: np.ndarray, factor: int) -> np.ndarray:
    """Room labels at `factor` times coarser cells: each block takes the label most of its free
    fine cells have (0 included, ties to the smaller label; a block with no free fine cell gets
    0); the partial blocks at the far edges are dropped, as `resample_map` drops them."""
    rows, cols = labels.shape[0] // factor, labels.shape[1] // factor
    fine_labels = np.asarray(labels)[: rows * factor, : cols * factor].astype(np.int64)
    fine_free = np.asarray(free, dtype=bool)[: rows * factor, : cols * factor]
    block = (np.arange(rows * factor)[:, None] // factor) * cols + np.arange(cols * factor)[None, :] // factor
    span = int(fine_labels.max()) + 1
    keys, counts = np.unique(block[fine_free] * span + fine_labels[fine_free], return_counts=True)
    order = np.lexsort((keys % span, -counts, keys // span))  # per block: most cells first, then the smaller label
    keys = keys[order]
    first = np.ones(len(keys), dtype=bool)
    first[1:] = keys[1:] // span != keys[:-1] // span
    out = np.zeros(rows * cols, dtype=np.int64)
    out[keys[first] // span] = keys[first] % span
    return out.reshape(rows, cols)


@dataclass(frozen=True)
class PlanGrid:
    """One real plan at STAT_CELL_M cells: its name, free grid (largest component) and room labels."""

    name: str
    free: np.ndarray
    rooms: np.ndarray | None


def real_plan_grids(
    folder: str | Path, resolution: float = 0.05, robot_radius_m: float = 0.2, cell_size: float = STAT_CELL_M
) -> list[PlanGrid]:
    """Every plan in `folder` at `cell_size` cells, free space by the plan import's rule
    (`convert_plan`) and room labels by block mode over the fine free cells."""
    grids = []
    for source in find_plan_sources(folder, resolution=resolution):
        plan = convert_plan(source, cell_size, robot_radius_m, starts=1, rng=np.random.default_rng(0))
        rooms = None
        if source.rooms is not None:
            factor = int(round(cell_size / source.resolution))
            rooms = block_mode_labels(source.rooms, source.free, factor)[: plan.free.shape[0], : plan.free.shape[1]]
        grids.append(PlanGrid(source.name, plan.free, rooms))
    return grids
