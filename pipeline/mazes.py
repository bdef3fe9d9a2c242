"""Procedural mazes in the "maze PNG" format of the DARE/GUIDE samples.

A maze is laid out on a square grid of blocks (5 m by default): a ring of wall blocks,
one-block-wide corridors from a perfect maze on the odd block positions (so walls are one
block thick), rectangular rooms of several blocks, dead ends pruned back until about 40 %
of the blocks are free (the samples leave solid wall regions), and a few extra wall openings
that close loops. The image is drawn at twice the grid resolution (one pixel = cell_size / 2)
with 127 for wall, 195 for free and 208 for the free start block, which is what
`pipeline.maps.load_maze_png` reads back.
"""

from __future__ import annotations

import math
import os
import tempfile
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

WALL_VALUE = 127
FREE_VALUE = 195
START_VALUE = 208  # must match pipeline.maps.MAZE_START_VALUE
MIN_SIDE_BLOCKS = 5  # ring + two corridors + the wall between them
MIN_BLOCK_PIXELS = 9  # a start block must keep >= 11 whole 208 cells after the 2x2 reduction
_INTEGER_TOLERANCE = 1e-6

AREA_UNIT_M = 100.0  # `rooms` and `extra_loops` are counts per AREA_UNIT_M x AREA_UNIT_M of maze
_START_ROOM_MIN = 3  # the start block is the centre of a room at least this many blocks a side
_START_ZONE = (0.3, 0.7)  # ... and the start room's centre lies in this middle share of each side
_CHILD_ATTEMPTS = 12  # placements tried beside a room before it counts as boxed in
_ROOM_SIDE_P = 0.5  # a room side is low + Binomial(high - low, p) blocks: middle sizes are commonest
_NEWEST_BIAS = 0.5  # chance to grow from the newest room (long chains) rather than a random one
_LOOP_MIN_DETOUR = 6  # an extra door must close a loop at least this many blocks around
_STEPS = ((-1, 0), (1, 0), (0, -1), (0, 1))


@dataclass(frozen=True)
class _Room:
    top: int
    left: int
    height: int
    width: int

    @property
    def slices(self) -> tuple[slice, slice]:
        return slice(self.top, self.top + self.height), slice(self.left, self.left + self.width)


@dataclass(frozen=True)
class MazeConfig:
    """What kind of mazes to draw; every range is inclusive.

    `side_m` bounds the side length in metres; a maze's side is a whole number of blocks
    drawn uniformly from the block counts inside that range. `free_fraction` is the share of
    free blocks that dead-end pruning aims at (the eight samples: 37-48 %, mean 41 %): a full
    maze fills the whole square, while the samples leave solid wall regions.
    """

    side_m: tuple[float, float]
    block_m: float = 5.0
    cell_size: float = 0.4
    rooms: tuple[int, int] = (17, 21)
    room_blocks: tuple[int, int] = (2, 4)
    extra_loops: int = 1
    free_fraction: tuple[float, float] = (0.36, 0.44)

    def __post_init__(self) -> None:
        # Coerce YAML lists to tuples so the frozen config stays hashable and comparable.
        object.__setattr__(self, "side_m", _pair(self.side_m, "side_m", float))
        object.__setattr__(self, "rooms", _pair(self.rooms, "rooms", int))
        object.__setattr__(self, "room_blocks", _pair(self.room_blocks, "room_blocks", int))
        object.__setattr__(self, "free_fraction", _pair(self.free_fraction, "free_fraction", float))
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
            raise ValueError(
                f"MazeConfig.side_m {self.side_m} holds no whole number of {self.block_m} m blocks"
            )
        if low_blocks < MIN_SIDE_BLOCKS:
            raise ValueError(
                f"MazeConfig.side_m {self.side_m} allows a side of {low_blocks} blocks; a maze needs at "
                f"least {MIN_SIDE_BLOCKS} blocks ({MIN_SIDE_BLOCKS * self.block_m} m) per side"
            )

        low_fraction, high_fraction = self.free_fraction
        if not 0 < low_fraction <= high_fraction <= 1:
            raise ValueError(f"MazeConfig.free_fraction must be a range 0 < low <= high <= 1, got {self.free_fraction}")
        if self.rooms[0] < 0 or self.rooms[0] > self.rooms[1]:
            raise ValueError(f"MazeConfig.rooms must be a range 0 <= low <= high, got {self.rooms}")
        room_low, room_high = self.room_blocks
        if room_low < 2 or room_low > room_high:
            # A room at least 2 blocks wide always covers an odd block position, i.e. a maze node,
            # which is what keeps every room joined to the corridors.
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


def _start_room(n: int, config: MazeConfig, rng: np.random.Generator) -> _Room:
    """A room at least 3 x 3 blocks (so its centre block has eight free neighbours) whose
    centre lies in the middle part of the maze, where the samples put their start."""
    top_side = max(_START_ROOM_MIN, min(config.room_blocks[1], n - 2))
    height, width = (int(v) for v in rng.integers(_START_ROOM_MIN, top_side + 1, size=2))
    rows, cols = [], []
    for size, out in ((height, rows), (width, cols)):
        first = max(1, int(round(n * _START_ZONE[0] - size / 2)))
        last = min(n - 1 - size, int(round(n * _START_ZONE[1] - size / 2)))
        out.append(int(rng.integers(first, max(first, last) + 1)))
    return _Room(rows[0], cols[0], height, width)


def _try_child(
    free: np.ndarray, parent: _Room, config: MazeConfig, rng: np.random.Generator
) -> tuple[_Room, tuple[int, int]] | None:
    """A random room beside `parent` across a one-block wall, and the door block joining
    them; None if it does not fit (outside the wall ring, or touching any other free block)."""
    n = free.shape[0]
    low, high = config.room_blocks
    height, width = (int(v) for v in low + rng.binomial(high - low, _ROOM_SIDE_P, size=2))
    side = int(rng.integers(4))
    if side < 2:  # above or below: the rooms share at least one column
        top = parent.top - 1 - height if side == 0 else parent.top + parent.height + 1
        left = int(rng.integers(parent.left - width + 1, parent.left + parent.width))
        door_row = top + height if side == 0 else top - 1
        door_col = int(rng.integers(max(left, parent.left), min(left + width, parent.left + parent.width)))
    else:  # left or right: the rooms share at least one row
        left = parent.left - 1 - width if side == 2 else parent.left + parent.width + 1
        top = int(rng.integers(parent.top - height + 1, parent.top + parent.height))
        door_col = left + width if side == 2 else left - 1
        door_row = int(rng.integers(max(top, parent.top), min(top + height, parent.top + parent.height)))
    if top < 1 or left < 1 or top + height > n - 1 or left + width > n - 1:
        return None
    # The room and the wall ring around it must be solid wall, so rooms never touch.
    if free[top - 1 : top + height + 1, left - 1 : left + width + 1].any():
        return None
    return _Room(top, left, height, width), (door_row, door_col)


def _grow_rooms(n: int, count: int, config: MazeConfig, rng: np.random.Generator) -> tuple[np.ndarray, _Room]:
    """Lay out up to `count` rooms as a tree grown from the start room; return the free
    blocks and the start room.

    Each new room sits one wall block away from an earlier room (usually the newest, which
    makes chains of rooms, else a random one, which makes branches) and is joined to it by
    a one-block door. A room that has no space left around it after _CHILD_ATTEMPTS tries
    stops growing. Rooms never touch one another, so every free block is in a rectangular
    room or is a door, as in the samples.
    """
    free = np.zeros((n, n), dtype=bool)
    start = _start_room(n, config, rng)
    free[start.slices] = True
    growing = [start]
    _ALL.append(start)
    placed = 1
    while placed < count and growing:
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
        growing.append(room)
        _ALL.append(room)
        placed += 1
    if _RETREE:
        rooms_only = np.zeros_like(free)
        for r in _ALL:
            rooms_only[r.slices] = True
        _ALL.clear()
        free = _spanning_doors(rooms_only, rng)
    return free, start


_ALL = []
_RETREE = False


def _spanning_doors(rooms: np.ndarray, rng):
    count, labels = cv2.connectedComponents(rooms.astype(np.uint8), connectivity=4)
    n = rooms.shape[0]
    doors = {}
    for row in range(1, n - 1):
        for col in range(1, n - 1):
            if rooms[row, col]:
                continue
            for (a, b), (c, d) in ((((row, col - 1), (row, col + 1)), ((row - 1, col), (row + 1, col))), (((row - 1, col), (row + 1, col)), ((row, col - 1), (row, col + 1)))):
                if rooms[a] and rooms[b] and not rooms[c] and not rooms[d]:
                    key = tuple(sorted((int(labels[a]), int(labels[b]))))
                    doors.setdefault(key, []).append((row, col))
    parent = list(range(count))
    def find(x):
        while parent[x] != x:
            parent[x] = parent[parent[x]]
            x = parent[x]
        return x
    free = rooms.copy()
    keys = sorted(doors)
    for i in rng.permutation(len(keys)):
        a, b = keys[i]
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[ra] = rb
            cells = doors[keys[i]]
            free[cells[int(rng.integers(len(cells)))]] = True
    return free


def _geodesic(free: np.ndarray, source: tuple[int, int]) -> np.ndarray:
    """Steps from `source` to every free block (4-connected); -1 where unreachable."""
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


def _open_loops(free: np.ndarray, count: int, rng: np.random.Generator) -> None:
    """Open up to `count` extra doors, each closing a loop at least _LOOP_MIN_DETOUR blocks long.

    A door is a wall block between two free blocks in a straight line whose other two
    neighbours are wall; the free space is connected already, so each one adds a loop.
    """
    for _ in range(count):
        inner = free[1:-1, 1:-1]
        up, down = free[:-2, 1:-1], free[2:, 1:-1]
        left, right = free[1:-1, :-2], free[1:-1, 2:]
        doorway = ((left & right) & ~up & ~down) | ((up & down) & ~left & ~right)
        candidates = np.argwhere(~inner & doorway) + 1
        for row, col in candidates[rng.permutation(len(candidates))]:
            if free[row, col - 1] and free[row, col + 1]:
                a, b = (row, col - 1), (row, col + 1)
            else:
                a, b = (row - 1, col), (row + 1, col)
            if _geodesic(free, a)[b] >= _LOOP_MIN_DETOUR:
                free[row, col] = True
                break
        else:
            return


def _is_connected(free: np.ndarray) -> bool:
    _, labels = cv2.connectedComponents(free.astype(np.uint8), connectivity=4)
    return bool(free.any()) and len(np.unique(labels[free])) == 1


def generate_block_grid(config: MazeConfig, rng: np.random.Generator) -> tuple[np.ndarray, tuple[int, int]]:
    """Draw one maze as a boolean block grid (True = free) and its start block (row, col)."""
    low, high = config.side_blocks
    n = int(rng.integers(low, high + 1))
    side_m = n * config.block_m
    free, start_room = _grow_rooms(n, max(1, _scaled_count(config.rooms, side_m, rng)), config, rng)
    _open_loops(free, _scaled_count((config.extra_loops, config.extra_loops), side_m, rng), rng)
    start = np.zeros_like(free)
    start[start_room.top + (start_room.height - 1) // 2, start_room.left + (start_room.width - 1) // 2] = True
    # A random rotation and flip spread any bias of the layout over all four sides.
    turns, flip = int(rng.integers(4)), bool(rng.random() < 0.5)
    free, start = (np.ascontiguousarray(np.rot90(g, turns)[:, ::-1] if flip else np.rot90(g, turns)) for g in (free, start))
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
    path.parent.mkdir(parents=True, exist_ok=True)
    handle, temp_name = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(handle, "wb") as stream:
            stream.write(encoded.tobytes())
        os.replace(temp_name, path)
    except BaseException:
        Path(temp_name).unlink(missing_ok=True)
        raise
    return path


def generate_maze_set(
    config: MazeConfig,
    count: int,
    out_dir: str | Path,
    seed: int | Sequence[int],
    prefix: str = "maze",
    progress: bool = True,
) -> list[Path]:
    """Write `count` mazes as `{prefix}_{i:04d}.png`, maze i drawn from default_rng([*seed, i]).

    Seeding each maze on its own makes maze i independent of `count` and of the others, so a
    set can be grown or regenerated piecewise with identical bytes.
    """
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 0:
        raise ValueError(f"count must be a non-negative integer, got {count!r}")
    base = [int(seed)] if isinstance(seed, (int, np.integer)) else [int(s) for s in seed]
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in tqdm(range(int(count)), desc=f"mazes -> {out_dir}", unit="maze", disable=not progress):
        image = generate_maze(config, np.random.default_rng([*base, i]))
        paths.append(write_maze_png(image, out_dir / f"{prefix}_{i:04d}.png"))
    return paths
