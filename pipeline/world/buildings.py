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

from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from pipeline.world.building_config import FREE_LABEL, FURNITURE_LABEL, OUTSIDE_LABEL, BuildingConfig, Rect
from pipeline.world.building_footprint import Drawing, draw_outline, layout_wings
from pipeline.world.building_rooms import cut_rooms, furnish, open_doors
from pipeline.world.floor_shape import plan_statistics
from pipeline.world.mazes import generate_map_set
from pipeline.world.offices import START_CELLS, draw_with_sides, render_free_map
from pipeline.world.reachability import reachable_free


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


# ---------------------------------------------------------------------------- the footprint


# ---------------------------------------------------------------------------- rooms


# ---------------------------------------------------------------------------- doors


# ---------------------------------------------------------------------------- furniture


# ---------------------------------------------------------------------------- start and reach
def _pick_start(drawing: Drawing) -> tuple[int, int]:
    """A start cell with free cells all round its START_CELLS square."""
    free = drawing.labels == FREE_LABEL
    clear = cv2.erode(free.astype(np.uint8), np.ones((2 * START_CELLS + 1,) * 2, np.uint8)).astype(bool)
    candidates = np.argwhere(clear)
    if not len(candidates):
        raise RuntimeError("building generator bug: no free cell has room for the start")
    row, col = candidates[int(drawing.rng.integers(len(candidates)))]
    return int(row), int(col)


def _close_unreachable(drawing: Drawing, start: tuple[int, int]) -> float:
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


def _room_record(drawing: Drawing) -> tuple[np.ndarray, tuple[Rect, ...]]:
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
        drawing = Drawing(config, rng)
        outer = drawing.draw_wall(config.outer_wall_m)
        drawing.corridor_wall = drawing.draw_wall(config.wall_m)
        wings = layout_wings(drawing, outer)
        draw_outline(drawing, wings, outer)
        cut_rooms(drawing, wings)
        open_doors(drawing)
        furnish(drawing)
        start = _pick_start(drawing)
        if _close_unreachable(drawing, start) <= MAX_CLOSED_SHARE:
            break
    room_labels, rooms = _room_record(drawing)
    phase = (start[0] % drawing.step, start[1] % drawing.step)
    return BuildingFloor(
        drawing.labels, start, drawing.step, phase, rooms, tuple(drawing.doors), tuple(drawing.walls), room_labels
    )


def generate_building(config: BuildingConfig, rng: np.random.Generator) -> np.ndarray:
    """Draw one building floor as a maze PNG image (127 wall, 195 free, 208 start square)."""
    floor = draw_building(config, rng)
    return render_free_map(floor.free, floor.start)


def generate_building_set(
    config: BuildingConfig,
    count: int,
    out_dir: str | Path,
    seed: int | Sequence[int],
    prefix: str = "building",
    progress: bool = True,
    side_m: tuple[float, float] | None = None,
) -> list[Path]:
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
