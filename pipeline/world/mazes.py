"""Procedural mazes in the "maze PNG" format of the DARE/GUIDE samples.

A maze is a square grid of blocks (5 m by default) inside a ring of wall blocks. Like the
benchmark's sample mazes, it is made of rectangular rooms 2 to 4 blocks a side that never
touch one another: every pair of rooms is at least one wall block apart, and rooms are
joined only through one-block doors. Chains of narrow rooms read as meandering corridors,
and the space the rooms leave unused stays solid wall. The rooms grow as a tree from a
start room near the middle (each new room one wall block beside an earlier one, with a
door between them), mostly flush with the side of the room they grow from so that walls
line up; then a few extra doors close long loops. The defaults match DARE's eight sample
mazes in their rooms, free share, corridors and loops, and in the distance `nearest_frontier`
needs to explore them.

The image is drawn at twice the grid resolution (one pixel = cell_size / 2) with 127 for
wall, 195 for free and 208 for the free start block, which is what
`pipeline.world.maps.load_maze_png` reads back.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import cv2
import numpy as np
from tqdm import tqdm

from pipeline.common.atomic import atomic_write_bytes
from pipeline.world.map_files import MAX_IMAGE_PIXELS

WALL_VALUE = 127
FREE_VALUE = 195
START_VALUE = 208  # must match pipeline.world.maps.MAZE_START_VALUE
MIN_SIDE_BLOCKS = 5  # the wall ring around a 3 x 3 start room
MIN_BLOCK_PIXELS = 9  # a start block must keep >= 11 whole 208 cells after the 2x2 reduction
AREA_UNIT_M = 100.0  # `rooms` and `extra_loops` are counts per AREA_UNIT_M x AREA_UNIT_M of maze
_INTEGER_TOLERANCE = 1e-6

# Layout constants, calibrated so that the generated 100 m mazes match the eight samples in
# free share, room sizes, door placement and nearest-frontier exploration distance.
_START_ROOM_MIN = 3  # the start block is the centre of a room at least 3 x 3 blocks ...
_START_ZONE = (0.3, 0.7)  # ... whose centre lies in this middle share of each side
_ROOM_SIDE_P = 0.5  # a room side is low + Binomial(high - low, p) blocks: middle sizes are commonest
_ALIGN_CHANCE = 0.8  # chance a new room is flush with one end of its parent's side
_NEWEST_BIAS = 0.7  # chance to grow from the newest room (chains) rather than a random one (branches)
_CHILD_ATTEMPTS = 100  # placements tried beside a room before it counts as boxed in
_LOOP_MIN_DETOUR = 6  # an extra door must close a loop at least this many blocks around ...
_LOOP_POWER = 2.0  # ... and is drawn with weight (walk around) ** _LOOP_POWER, so loops are long
_STEPS = ((-1, 0), (1, 0), (0, -1), (0, 1))


@dataclass(frozen=True)
class _Room:
    """A rectangle of free blocks; `side` is where it lies beside the room it grew from
    (0 above, 1 below, 2 left, 3 right; -1 for the start room)."""

    top: int
    left: int
    height: int
    width: int
    side: int = -1

    @property
    def slices(self) -> tuple[slice, slice]:
        return slice(self.top, self.top + self.height), slice(self.left, self.left + self.width)


@dataclass(frozen=True)
class MazeConfig:
    """What kind of mazes to draw; every range is inclusive.

    `side_m` bounds the side length in metres; a maze's side is a whole number of blocks
    drawn uniformly from the block counts inside that range.

    `rooms` and `extra_loops` are densities, given per 100 m x 100 m (AREA_UNIT_M): a maze
    of side s metres draws a count from `rooms` and scales it by (s / 100) ** 2, rounded (at
    least one room, the start room), and gets round(extra_loops * (s / 100) ** 2) extra
    loop-closing doors. So a 180 m maze has 3.24 times the rooms of a 100 m one and the
    same room density. The default (17-21 rooms, one loop) is what the eight 100 m samples
    have; rooms stop growing early when a maze has no space left for them.

    `room_blocks` bounds each room side in blocks (the samples: 2 to 4); the start room is
    at least 3 x 3 blocks whatever the range.
    """

    side_m: tuple[float, float]
    block_m: float = 5.0
    cell_size: float = 0.4
    rooms: tuple[int, int] = (17, 21)
    room_blocks: tuple[int, int] = (2, 4)
    extra_loops: int = 1

    def __post_init__(self) -> None:
        # Coerce YAML lists to tuples so the frozen config stays hashable and comparable.
        object.__setattr__(self, "side_m", _pair(self.side_m, "side_m", float))
        object.__setattr__(self, "rooms", _pair(self.rooms, "rooms", int))
        object.__setattr__(self, "room_blocks", _pair(self.room_blocks, "room_blocks", int))
        for name in ("block_m", "cell_size"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"MazeConfig.{name} must be a positive number, got {value!r}")
        if isinstance(self.extra_loops, bool) or not isinstance(self.extra_loops, (int, np.integer)):
            raise ValueError(f"MazeConfig.extra_loops must be an integer, got {self.extra_loops!r}")
        if self.extra_loops < 0:
            raise ValueError(f"MazeConfig.extra_loops must be >= 0, got {self.extra_loops}")

        exact_pixels = self.block_m / (self.cell_size / 2)
        if abs(exact_pixels - round(exact_pixels)) > _INTEGER_TOLERANCE:
            raise ValueError(
                f"MazeConfig.block_m ({self.block_m} m) must be a whole number of pixels of "
                f"{self.cell_size / 2} m (cell_size / 2), got {exact_pixels:.6g} pixels"
            )
        if round(exact_pixels) < MIN_BLOCK_PIXELS:
            raise ValueError(
                f"MazeConfig.block_m ({self.block_m} m) is {round(exact_pixels)} pixels; at least "
                f"{MIN_BLOCK_PIXELS} are needed so the start block survives the loader's 2x2 reduction"
            )

        low_m, high_m = self.side_m
        if not (math.isfinite(low_m) and math.isfinite(high_m)) or low_m <= 0 or low_m > high_m:
            raise ValueError(f"MazeConfig.side_m must be a range 0 < low <= high, got {self.side_m}")
        low_blocks, high_blocks = self.side_blocks
        if low_blocks > high_blocks:
            raise ValueError(f"MazeConfig.side_m {self.side_m} holds no whole number of {self.block_m} m blocks")
        if low_blocks < MIN_SIDE_BLOCKS:
            raise ValueError(
                f"MazeConfig.side_m {self.side_m} allows a side of {low_blocks} block{'s' if low_blocks != 1 else ''}; a maze needs at "
                f"least {MIN_SIDE_BLOCKS} blocks ({MIN_SIDE_BLOCKS * self.block_m} m) per side"
            )
        max_blocks = math.isqrt(MAX_IMAGE_PIXELS) // self.block_pixels  # what the map loader reads back
        if high_blocks > max_blocks:
            raise ValueError(
                f"MazeConfig.side_m {self.side_m}: a side of {high_blocks} blocks is an image of "
                f"{high_blocks * self.block_pixels} pixels square, more than the map loader reads; "
                f"the largest side at {self.cell_size:g} m cells is {max_blocks * self.block_m:g} m"
            )

        if self.rooms[0] < 0 or self.rooms[0] > self.rooms[1]:
            raise ValueError(f"MazeConfig.rooms must be a range 0 <= low <= high, got {self.rooms}")
        room_low, room_high = self.room_blocks
        if room_low < 2 or room_low > room_high:
            # One-block-wide rooms would be dead-end corridors, which the samples do not have.
            raise ValueError(f"MazeConfig.room_blocks must be a range 2 <= low <= high, got {self.room_blocks}")
        if room_high > low_blocks - 2:
            raise ValueError(
                f"MazeConfig.room_blocks {self.room_blocks}: a room of {room_high} blocks does not fit inside "
                f"the wall ring of the smallest maze ({low_blocks} blocks per side)"
            )

    @property
    def block_pixels(self) -> int:
        """Pixels per block side in the image (the image has two pixels per grid cell)."""
        return int(round(self.block_m / (self.cell_size / 2)))

    @property
    def side_blocks(self) -> tuple[int, int]:
        """The inclusive range of side lengths in whole blocks that fit in `side_m`."""
        low_m, high_m = self.side_m
        low = math.ceil(low_m / self.block_m - _INTEGER_TOLERANCE)
        high = math.floor(high_m / self.block_m + _INTEGER_TOLERANCE)
        return low, high


def _pair(value: object, name: str, kind: type) -> tuple:
    """Turn a 2-element sequence into a tuple of `kind`, or explain why it is not a range."""
    if isinstance(value, (str, bytes)) or not isinstance(value, Sequence) or len(value) != 2:
        raise ValueError(f"MazeConfig.{name} must be a pair [low, high], got {value!r}")
    items = []
    for item in value:
        if isinstance(item, bool) or not isinstance(item, (int, float, np.integer, np.floating)):
            raise ValueError(f"MazeConfig.{name} must hold numbers, got {value!r}")
        if kind is int and float(item) != int(item):
            raise ValueError(f"MazeConfig.{name} must hold whole numbers, got {value!r}")
        items.append(kind(item))
    return tuple(items)


def _scaled_count(per_area: tuple[int, int], side_m: float, rng: np.random.Generator) -> int:
    """Draw a count from a range given per AREA_UNIT_M x AREA_UNIT_M and scale it by the maze's area."""
    drawn = int(rng.integers(per_area[0], per_area[1] + 1))
    return int(round(drawn * (side_m / AREA_UNIT_M) ** 2))


def _room_size(config: MazeConfig, rng: np.random.Generator) -> tuple[int, int]:
    """(height, width) of a new room: each side low + Binomial(high - low, _ROOM_SIDE_P)."""
    low, high = config.room_blocks
    height, width = low + rng.binomial(high - low, _ROOM_SIDE_P, size=2)
    return int(height), int(width)


def _start_room(n: int, config: MazeConfig, rng: np.random.Generator) -> _Room:
    """A room at least 3 x 3 blocks (so its centre block has eight free neighbours) whose
    centre lies in the middle part of the maze, where the samples put their start."""
    largest = max(_START_ROOM_MIN, min(config.room_blocks[1], n - 2))
    height, width = (int(v) for v in rng.integers(_START_ROOM_MIN, largest + 1, size=2))
    corner = []
    for size in (height, width):
        first = max(1, int(round(n * _START_ZONE[0] - size / 2)))
        last = min(n - 1 - size, int(round(n * _START_ZONE[1] - size / 2)))
        corner.append(int(rng.integers(first, max(first, last) + 1)))
    return _Room(corner[0], corner[1], height, width)


def _offset(parent_start: int, parent_size: int, size: int, rng: np.random.Generator) -> int:
    """Where a new room starts along the side it shares with its parent: usually flush with
    one end of the parent's side (so walls line up, as in the samples), else anywhere that
    still shares at least one block with it."""
    if rng.random() < _ALIGN_CHANCE:
        return parent_start if rng.random() < 0.5 else parent_start + parent_size - size
    return int(rng.integers(parent_start - size + 1, parent_start + parent_size))


def _try_child(
    free: np.ndarray, parent: _Room, config: MazeConfig, rng: np.random.Generator
) -> tuple[_Room, tuple[int, int]] | None:
    """A random room one wall block beside `parent` and the door block joining them; None if
    it does not fit (it would cross the wall ring or touch any other free block)."""
    n = free.shape[0]
    height, width = _room_size(config, rng)
    side = int(rng.integers(4))
    if side < 2:  # above or below: the rooms share at least one column
        top = parent.top - 1 - height if side == 0 else parent.top + parent.height + 1
        left = _offset(parent.left, parent.width, width, rng)
        door_row = top + height if side == 0 else top - 1
        door_col = int(rng.integers(max(left, parent.left), min(left + width, parent.left + parent.width)))
    else:  # left or right: the rooms share at least one row
        left = parent.left - 1 - width if side == 2 else parent.left + parent.width + 1
        top = _offset(parent.top, parent.height, height, rng)
        door_col = left + width if side == 2 else left - 1
        door_row = int(rng.integers(max(top, parent.top), min(top + height, parent.top + parent.height)))
    if top < 1 or left < 1 or top + height > n - 1 or left + width > n - 1:
        return None
    # The room and a one-block margin around it must be wall, so rooms never touch. The door
    # lies in that margin, so it is wall too, and its two side neighbours are in the margins
    # of both rooms: every door is a single block between exactly two rooms.
    if free[top - 1 : top + height + 1, left - 1 : left + width + 1].any():
        return None
    return _Room(top, left, height, width, side), (door_row, door_col)


def _grow_rooms(n: int, count: int, config: MazeConfig, rng: np.random.Generator) -> tuple[np.ndarray, list[_Room]]:
    """Lay out up to `count` rooms as a tree grown from the start room (rooms[0]).

    Each new room grows from the newest room still growing (with chance _NEWEST_BIAS,
    which makes chains) or from a random one (which makes branches), one wall block away
    and joined to it by a one-block door. A room with no space left beside it after
    _CHILD_ATTEMPTS tries stops growing, so a maze too small for `count` rooms is simply full.
    """
    free = np.zeros((n, n), dtype=bool)
    rooms = [_start_room(n, config, rng)]
    free[rooms[0].slices] = True
    growing = [rooms[0]]
    while len(rooms) < count and growing:
        index = len(growing) - 1 if rng.random() < _NEWEST_BIAS else int(rng.integers(len(growing)))
        for _ in range(_CHILD_ATTEMPTS):
            child = _try_child(free, growing[index], config, rng)
            if child is not None:
                break
        if child is None:
            growing.pop(index)
            continue
        room, door = child
        free[room.slices] = True
        free[door] = True
        rooms.append(room)
        growing.append(room)
    return free, rooms


def _geodesic(free: np.ndarray, source: tuple[int, int]) -> np.ndarray:
    """Steps from `source` to every free block (4-connected); -1 where unreachable.
    `free` must have a wall border, as every maze grid has."""
    dist = np.full(free.shape, -1, dtype=np.int32)
    dist[source] = 0
    frontier = [source]
    while frontier:
        following = []
        for row, col in frontier:
            for dr, dc in _STEPS:
                r, c = row + dr, col + dc
                if free[r, c] and dist[r, c] < 0:
                    dist[r, c] = dist[row, col] + 1
                    following.append((r, c))
        frontier = following
    return dist


def _door_sites(free: np.ndarray, label: np.ndarray) -> list[tuple[tuple[int, int], tuple[int, int], tuple[int, int]]]:
    """Every block between two different rooms in a straight line whose other two neighbours
    are wall, as (block, one room's block, the other room's block), in row-major order."""
    sites = []
    inner = (slice(1, -1), slice(1, -1))
    up, down = label[:-2, 1:-1], label[2:, 1:-1]
    left, right = label[1:-1, :-2], label[1:-1, 2:]
    free_up, free_down = free[:-2, 1:-1], free[2:, 1:-1]
    free_left, free_right = free[1:-1, :-2], free[1:-1, 2:]
    across = (left >= 0) & (right >= 0) & (left != right) & ~free_up & ~free_down
    along = (up >= 0) & (down >= 0) & (up != down) & ~free_left & ~free_right
    not_room = label[inner] < 0
    for row, col in np.argwhere(not_room & (across | along)) + 1:
        if across[row - 1, col - 1]:
            sites.append(((row, col), (row, col - 1), (row, col + 1)))
        else:
            sites.append(((row, col), (row - 1, col), (row + 1, col)))
    return sites


def _open_loops(free: np.ndarray, rooms: list[_Room], count: int, rng: np.random.Generator) -> None:
    """Add up to `count` doors between rooms that are one wall block apart but not yet joined.

    Each candidate pair of rooms gets one random door block; pairs whose walk around is
    shorter than _LOOP_MIN_DETOUR blocks are skipped and the rest are drawn with weight
    (walk around) ** _LOOP_POWER. Long loops like the samples' let an explorer go round
    instead of back, which is much of why the samples explore quickly.
    """
    label = np.full(free.shape, -1, dtype=np.int32)
    for index, room in enumerate(rooms):
        label[room.slices] = index
    open_pairs: dict[tuple[Any, Any], list[tuple[tuple[int, int], tuple[int, int], tuple[int, int]]]]
    for _ in range(count):
        joined, open_pairs = set(), {}
        for block, a, b in _door_sites(free, label):
            pair = (min(label[a], label[b]), max(label[a], label[b]))
            if free[block]:
                joined.add(pair)
            else:
                open_pairs.setdefault(pair, []).append((block, a, b))
        blocks, weights = [], []
        for pair in sorted(set(open_pairs) - joined):
            block, a, b = open_pairs[pair][int(rng.integers(len(open_pairs[pair])))]
            detour = int(_geodesic(free, a)[b])
            if detour >= _LOOP_MIN_DETOUR:
                blocks.append(block)
                weights.append(float(detour) ** _LOOP_POWER)
        if not blocks:
            return
        chosen = int(rng.choice(len(blocks), p=np.asarray(weights) / sum(weights)))
        free[tuple(blocks[chosen])] = True


def _is_connected(free: np.ndarray) -> bool:
    _, labels = cv2.connectedComponents(free.astype(np.uint8), connectivity=4)
    return bool(free.any()) and len(np.unique(labels[free])) == 1


def generate_block_grid(config: MazeConfig, rng: np.random.Generator) -> tuple[np.ndarray, tuple[int, int]]:
    """Draw one maze as a boolean block grid (True = free) and its start block (row, col)."""
    low, high = config.side_blocks
    n = int(rng.integers(low, high + 1))
    side_m = n * config.block_m
    free, rooms = _grow_rooms(n, max(1, _scaled_count(config.rooms, side_m, rng)), config, rng)
    _open_loops(free, rooms, _scaled_count((config.extra_loops, config.extra_loops), side_m, rng), rng)
    start = np.zeros_like(free)
    first = rooms[0]
    start[first.top + (first.height - 1) // 2, first.left + (first.width - 1) // 2] = True
    # A random rotation and flip spread any bias of the layout over all four sides.
    turns, flip = int(rng.integers(4)), bool(rng.random() < 0.5)
    free, start = (np.rot90(grid, turns) for grid in (free, start))
    free, start = (np.ascontiguousarray(grid[:, ::-1] if flip else grid) for grid in (free, start))
    if free[0].any() or free[-1].any() or free[:, 0].any() or free[:, -1].any() or not _is_connected(free):
        raise RuntimeError("maze generator bug: free space touches the border ring or is disconnected")
    row, col = np.argwhere(start)[0]
    return free, (int(row), int(col))


def render_maze(free: np.ndarray, start: tuple[int, int], block_pixels: int) -> np.ndarray:
    """Draw a block grid as a maze PNG image: block_pixels x block_pixels pixels per block."""
    blocks = np.where(free, FREE_VALUE, WALL_VALUE).astype(np.uint8)
    blocks[start] = START_VALUE
    return np.kron(blocks, np.ones((block_pixels, block_pixels), dtype=np.uint8))


def generate_maze(config: MazeConfig, rng: np.random.Generator) -> np.ndarray:
    """Draw one maze as a uint8 image holding only 127 (wall), 195 (free) and 208 (start block)."""
    free, start = generate_block_grid(config, rng)
    return render_maze(free, start, config.block_pixels)


def write_maze_png(image: np.ndarray, path: str | Path) -> Path:
    """Write a uint8 gray image as PNG, atomically, so a crash never leaves a half-written maze.

    The bytes depend only on the pixels (cv2's PNG encoder stores no timestamp), which keeps
    DVC outputs reproducible.
    """
    path = Path(path)
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 2:
        raise ValueError(f"expected a 2-D uint8 image, got {image.dtype} of shape {image.shape}")
    ok, encoded = cv2.imencode(".png", image)
    if not ok:
        raise OSError(f"{path}: PNG encoding failed")
    atomic_write_bytes(path, encoded.tobytes())
    return path


def generate_maze_set(
    config: MazeConfig,
    count: int,
    out_dir: str | Path,
    seed: int | Sequence[int],
    prefix: str = "maze",
    progress: bool = True,
) -> list[Path]:
    """Write `count` mazes as `{prefix}_{i:04d}.png`, maze i drawn from default_rng([*seed, i])."""
    return generate_map_set(lambda rng: generate_maze(config, rng), count, out_dir, seed, prefix, progress)


def generate_map_set(
    draw: Callable[[np.random.Generator], np.ndarray],
    count: int,
    out_dir: str | Path,
    seed: int | Sequence[int],
    prefix: str,
    progress: bool = True,
) -> list[Path]:
    """Write `count` map images `draw(rng)` as `{prefix}_{i:04d}.png`, map i drawn from default_rng([*seed, i]).

    Seeding each map on its own makes map i independent of `count` and of the others, so a
    set can be grown or regenerated piecewise with identical bytes.
    """
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 0:
        raise ValueError(f"count must be a non-negative integer, got {count!r}")
    base = [int(seed)] if isinstance(seed, (int, np.integer)) else [int(s) for s in seed]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in tqdm(range(int(count)), desc=f"{prefix}s -> {out_dir}", unit=prefix, disable=not progress):
        paths.append(write_maze_png(draw(np.random.default_rng([*base, i])), out_dir / f"{prefix}_{i:04d}.png"))
    return paths
