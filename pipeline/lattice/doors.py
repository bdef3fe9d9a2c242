"""Door nodes: where a straight lattice edge misses a gap in a wall, a node in the gap joins its ends.

At a building's scale a door (0.6-1.2 m) is narrower than the 1 m lattice is regular: the edge
between two nodes on either side of a wall is a straight walk that crosses the wall where it
does, and passes the door only if it happens to meet the gap. A *door node* is a known-free,
passable cell that sees both ends of such an edge by the protocol's walk, the one with the
shortest two-segment way round (ties: the one farthest from walls). The edge then counts as
valid through it, with that way's length, and a robot sent along the edge drives through the
door node first (`via_waypoints`). Unlike DARE's lattice, whose edges are straight walks only,
the door-aware graph's node set is the lattice plus these cells, which lie off the lattice.

A door node lies where the known free space narrows: a wall's gap, the space between furniture,
or round a corner, anywhere two nodes see a common cell but not each other.
"""

from __future__ import annotations

import numba
import numpy as np

from pipeline.world.geometry import segment_is_known_free

Cell = tuple[int, int]  # (col, row)

MAX_DETOUR = 2.0  # a door node's way round is at most this many times the straight edge


def find_door_node(
    passable: np.ndarray, clearance: np.ndarray, a: Cell, b: Cell, max_detour: float = MAX_DETOUR
) -> tuple[Cell, float] | None:
    """(the door node between cells `a` and `b`, the length of the way through it in cells), or None
    when no passable cell sees both through passable cells within `max_detour` times |ab|."""
    found, length = _door_node(
        np.ascontiguousarray(passable, dtype=np.bool_),
        np.ascontiguousarray(clearance, dtype=np.float32),
        a[0],
        a[1],
        b[0],
        b[1],
        max_detour,
    )
    if found < 0:
        return None
    cols = passable.shape[1]
    return (int(found % cols), int(found // cols)), float(length)


def via_waypoints(
    passable: np.ndarray, clearance: np.ndarray, start: Cell, cells: list[Cell]
) -> list[tuple[Cell, bool]]:
    """`cells` (a route from `start`) with a door node before each one that `passable` does not join
    straight to the one before it, where a door node does: (cell, whether it is a door node) each.
    A segment that neither joins is kept as it is (its walk may be free by the time the robot gets
    there)."""
    route: list[tuple[Cell, bool]] = []
    here = start
    for cell in cells:
        if not segment_is_known_free(passable, here, cell):
            door = find_door_node(passable, clearance, here, cell)
            if door is not None:
                route.append((door[0], True))
        route.append((cell, False))
        here = cell
    return route


# `pipeline.world.geometry.walk_offsets`' walk, compiled: the door search tests thousands of walks
# an update, each ending at its first blocked cell, where the cached offset tables would be built.
@numba.njit(cache=True, nogil=True)
def walk_is_clear(free, x0, y0, x1, y1):  # pragma: no cover - compiled
    """The protocol's 4-connected walk from (x0, y0) to (x1, y1) visits only `free` cells, both ends."""
    rows, cols = free.shape
    dx, dy = abs(x1 - x0), abs(y1 - y0)
    sx = 1 if x1 > x0 else -1
    sy = 1 if y1 > y0 else -1
    err = dx - dy
    x, y = x0, y0
    for _ in range(dx + dy + 1):
        if x < 0 or x >= cols or y < 0 or y >= rows or not free[y, x]:
            return False
        if err > 0:
            x += sx
            err -= 2 * dy
        else:
            y += sy
            err += 2 * dx
    return True


@numba.njit(cache=True, nogil=True)
def segment_clear(free, x0, y0, x1, y1):  # pragma: no cover - compiled
    """The motion rule: the walk in either direction is clear."""
    return walk_is_clear(free, x0, y0, x1, y1) or walk_is_clear(free, x1, y1, x0, y0)


@numba.njit(cache=True, nogil=True)
def _door_node(passable, clearance, ax, ay, bx, by, max_detour):  # pragma: no cover - compiled
    rows, cols = passable.shape
    straight = np.hypot(bx - ax, by - ay)
    budget = max_detour * straight
    # The cells whose way round is within budget lie in an ellipse with foci a and b; search its box.
    half = int(np.ceil(budget / 2.0))
    mx, my = (ax + bx) // 2, (ay + by) // 2
    best, best_length, best_clear = -1, np.inf, -1.0
    for y in range(max(0, my - half), min(rows, my + half + 1)):
        for x in range(max(0, mx - half), min(cols, mx + half + 1)):
            if not passable[y, x]:
                continue
            length = np.hypot(x - ax, y - ay) + np.hypot(bx - x, by - y)
            if length > budget + 1e-9 or length > best_length + 1e-9:
                continue
            if length >= best_length - 1e-9 and clearance[y, x] <= best_clear:
                continue
            if segment_clear(passable, ax, ay, x, y) and segment_clear(passable, x, y, bx, by):
                best, best_length, best_clear = y * cols + x, length, clearance[y, x]
    return best, best_length


@numba.njit(cache=True, nogil=True)
def door_edges_kernel(
    valid,
    via,
    via_length,
    edge_box,
    box,
    edge_nodes,
    node_cells,
    node_free,
    passable,
    clearance,
    wx0,
    wy0,
    cols,
    cell_size,
    max_detour,
):  # pragma: no cover - compiled
    """For each edge meeting `box` between free nodes, not straight-valid: straight again when its
    walk is now clear (then `via` -1), else valid through its best door node in the window
    `passable` / `clearance` (offset `wx0`, `wy0` in a grid of `cols` columns). Whether any changed."""
    x0, x1, y0, y1 = box[0], box[1], box[2], box[3]
    free = passable  # straight walks need known-free cells; the window's passable cells are those or fewer
    changed = False
    for e in range(valid.shape[0]):
        if valid[e] and via[e] < 0:
            continue
        if edge_box[e, 0] > x1 or edge_box[e, 1] < x0 or edge_box[e, 2] > y1 or edge_box[e, 3] < y0:
            continue
        a, b = edge_nodes[e, 0], edge_nodes[e, 1]
        if not (node_free[a] and node_free[b]):
            continue
        ax, ay = node_cells[a, 0] - wx0, node_cells[a, 1] - wy0
        bx, by = node_cells[b, 0] - wx0, node_cells[b, 1] - wy0
        if via[e] >= 0 and segment_clear(free, ax, ay, bx, by):
            via[e] = -1
            changed = True
            continue
        found, length = _door_node(passable, clearance, ax, ay, bx, by, max_detour)
        if found < 0:
            continue
        flat = (found // passable.shape[1] + wy0) * cols + found % passable.shape[1] + wx0
        metres = length * cell_size
        if not valid[e] or metres < via_length[e] - 1e-9:
            valid[e] = True
            via[e] = flat
            via_length[e] = metres
            changed = True
    return changed
