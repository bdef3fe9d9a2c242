"""A building floor's inside: rooms cut from the strips beside the corridors, their doors, and
furniture that occludes the lidar.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from pipeline.world.building_config import CORRIDOR, FREE_LABEL, FURNITURE_LABEL, WALL_LABEL, Rect
from pipeline.world.building_footprint import Drawing, Wing, rect_slices, room_boxes


def cut_rooms(drawing: Drawing, wings: list[Wing]) -> None:
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
            for rect in (
                (top - wall, left - wall, top, right + wall),
                (bottom, left - wall, bottom + wall, right + wall),
                (top, left - wall, bottom, left),
                (top, right, bottom, right + wall),
            ):
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


def _cut_strip(
    drawing: Drawing, piece: np.ndarray, horizontal: bool, caps: list[int], next_id: int, turned: bool = False
) -> int:
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


def _split_deep_room(drawing: Drawing, mask: np.ndarray, horizontal: bool, next_id: int) -> int:
    """Perhaps split a room deep enough for two along its strip (`horizontal`: along the rows)
    into two rooms, one behind the other: one that keeps no corridor wall is reached through the
    other (`open_doors`). Returns the next free room id."""
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


def _drop_slivers(drawing: Drawing) -> None:
    """Rooms too small or too narrow for a door and a robot (left where wings meet) become solid."""
    config, labels, region = drawing.config, drawing.labels, drawing.region
    least = config.cells(config.door_m[1]) + 2
    for room, box in room_boxes(region).items():
        crop = rect_slices(box)
        mask = region[crop] == room
        if min(box[2] - box[0], box[3] - box[1]) < least or mask.sum() < least * least:
            labels[crop][mask], region[crop][mask] = WALL_LABEL, 0


def _door_places(drawing: Drawing, room: int, goal: np.ndarray, width: int) -> list[Rect]:
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


def _open_door(drawing: Drawing, room: int, goal: np.ndarray, width: int | None = None) -> bool:
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


def open_doors(drawing: Drawing) -> None:
    """One door per room onto a corridor where it has a corridor wall; rooms without one open
    into a neighbouring room that is reached already; then second doors (more for large rooms,
    mostly onto a corridor); a few rooms open onto their corridor over their whole side instead
    (lobbies)."""
    config, region = drawing.config, drawing.region
    drawing.boxes = room_boxes(region)
    ids = sorted(drawing.boxes)
    order = [ids[i] for i in drawing.rng.permutation(len(ids))]
    slots = max(ids, default=0) + 2  # lookups per region id + 1: CORRIDOR at 0, wall at 1
    corridor = np.zeros(slots, dtype=bool)
    corridor[0] = True
    rooms = np.ones(slots, dtype=bool)
    rooms[:2] = False
    reached = corridor.copy()
    cell_m2 = config.cell_size**2
    area = {room: float((region[rect_slices(drawing.boxes[room])] == room).sum()) * cell_m2 for room in ids}
    for room in order:
        if area[room] <= config.large_room_m2 and drawing.chance(config.open_room_chance) and _open_room(drawing, room):
            continue
        reached[room + 1] = _open_door(drawing, room, corridor)
    waiting = [
        room for room in order if not reached[room + 1] and (region[rect_slices(drawing.boxes[room])] == room).any()
    ]
    while waiting:
        opened = [room for room in waiting if _open_door(drawing, room, reached)]
        reached[[room + 1 for room in opened]] = True
        waiting = [room for room in waiting if room not in opened]
        if not opened:
            break
    for room in waiting:  # no wall it shares with anything reached: locked, solid
        crop = rect_slices(drawing.boxes[room])
        mask = region[crop] == room
        drawing.labels[crop][mask], region[crop][mask] = WALL_LABEL, 0
    for room in order:
        if not reached[room + 1] or not (region[rect_slices(drawing.boxes[room])] == room).any():
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


def _open_room(drawing: Drawing, room: int) -> bool:
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
    crop = rect_slices(drawing.boxes[room])
    drawing.region[crop][drawing.region[crop] == room] = CORRIDOR
    drawing.doors.append((top, left, bottom, right))
    return True


def furnish(drawing: Drawing) -> None:
    """Tables, shelves along walls, partial walls in large rooms and (in halls) a row of columns,
    kept clear of the doors; a piece that would cut its room in two is not placed."""
    config, rng, labels, region = drawing.config, drawing.rng, drawing.labels, drawing.region
    n = drawing.n
    keep_clear = np.zeros((n, n), dtype=bool)
    clearance = config.cells(config.door_clearance_m)
    for top, left, bottom, right in drawing.doors:
        keep_clear[
            max(0, top - clearance) : min(n, bottom + clearance), max(0, left - clearance) : min(n, right + clearance)
        ] = True
    for room, (top, left, bottom, right) in room_boxes(region).items():
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
