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

import heapq
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

AREA_UNIT_M = 100.0  # `rooms` and `extra_loops` are counts per AREA_UNIT_M x AREA_UNIT_M
_START_ZONE = (0.3, 0.7)  # the start room's centre lies in this middle share of each side
_ROOM_ATTEMPTS = 60
_MERGE_CHANCE = 0.35
_JITTER = 1.0
_BESIDE_PENALTY = 1.5
_LOOP_MIN_DETOUR = 8
_STEPS = ((-1, 0), (1, 0), (0, -1), (0, 1))


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
    rooms: tuple[int, int] = (14, 20)
    room_blocks: tuple[int, int] = (2, 4)
    extra_loops: int = 4
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


def _scaled_count(per_100m: tuple[int, int], side_m: float, rng: np.random.Generator) -> int:
    """Draw a count from a per-100 m x 100 m range and scale it by the maze's area."""
    drawn = int(rng.integers(per_100m[0], per_100m[1] + 1))
    return int(round(drawn * (side_m / AREA_UNIT_M) ** 2))


def _place_rooms(n: int, count: int, config: MazeConfig, rng: np.random.Generator) -> np.ndarray:
    """Lay out `count` rooms; return the region label of every block (-1 = wall).

    Room 0 is the 3 x 3 start room near the middle. A room keeps at least one wall block
    from the others, except that with chance _MERGE_CHANCE it may touch or overlap one and
    the two become one larger (L-shaped, T-shaped ...) area.
    """
    region = np.full((n, n), -1, dtype=np.int32)
    middle_low, middle_high = max(1, int(n * _START_ZONE[0]) - 1), min(n - 4, int(n * _START_ZONE[1]) - 1)
    top = int(rng.integers(middle_low, max(middle_low, middle_high) + 1))
    left = int(rng.integers(middle_low, max(middle_low, middle_high) + 1))
    region[top : top + 3, left : left + 3] = 0
    labels = 1
    low, high = config.room_blocks
    for _ in range(count - 1):
        for _attempt in range(_ROOM_ATTEMPTS):
            height, width = (int(v) for v in rng.integers(low, high + 1, size=2))
            top = int(rng.integers(1, n - height))  # rows 1 .. n-1-height, so the room ends by row n-2
            left = int(rng.integers(1, n - width))
            near = region[top - 1 : top + height + 1, left - 1 : left + width + 1]
            touched = np.unique(near[near >= 0])
            if touched.size == 0:
                region[top : top + height, left : left + width] = labels
                labels += 1
                break
            if touched.size == 1 and rng.random() < _MERGE_CHANCE:
                inside = region[top : top + height, left : left + width]
                if (inside >= 0).sum() <= inside.size // 2:  # grow the area, do not just pad it
                    region[top : top + height, left : left + width] = touched[0]
                    break
    # Relabel by 4-connected component (a merged room may touch its partner only at a corner).
    _, components = cv2.connectedComponents((region >= 0).astype(np.uint8), connectivity=4)
    start_label = components[region == 0][0]
    relabelled = np.where(region >= 0, components, -1)
    relabelled[components == start_label] = 0
    relabelled[(components == 0) & (region >= 0)] = start_label
    return relabelled


def _cheapest_path(tree: np.ndarray, free: np.ndarray, cost: np.ndarray) -> list[tuple[int, int]]:
    """Wall blocks of the cheapest path from `tree` to the nearest free block outside it."""
    n = free.shape[0]
    best = np.full((n, n), np.inf)
    parent: dict[tuple[int, int], tuple[int, int]] = {}
    heap = []
    for row, col in np.argwhere(tree):
        best[row, col] = 0.0
        heap.append((0.0, int(row), int(col)))
    heapq.heapify(heap)
    while heap:
        dist, row, col = heapq.heappop(heap)
        if dist > best[row, col]:
            continue
        if free[row, col] and not tree[row, col]:
            path = []
            cell = parent.get((row, col))
            while cell is not None and not tree[cell]:
                path.append(cell)
                cell = parent.get(cell)
            return path
        if free[row, col] and dist > 0:
            continue
        for dr, dc in _STEPS:
            r, c = row + dr, col + dc
            if not (1 <= r < n - 1 and 1 <= c < n - 1) or tree[r, c]:
                continue
            step = 0.0 if free[r, c] else cost[r, c]
            if dist + step < best[r, c]:
                best[r, c] = dist + step
                parent[(r, c)] = (row, col)
                heapq.heappush(heap, (dist + step, r, c))
    raise RuntimeError("maze generator bug: a room cannot be reached")


def _connect_regions(region: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Join every region to the start room with corridors; return the free blocks.

    Prim-like: the region nearest to the connected part is joined next, by the cheapest
    path through wall, where each wall block costs 1 plus a random jitter (so corridors
    meander) plus a penalty for running alongside free blocks (so corridors stay one block
    wide and keep a wall between them and the rooms). Rooms one block apart get a doorway.
    """
    free = region >= 0
    jitter = 1.0 + _JITTER * rng.random(free.shape)
    tree = region == 0
    while (free & ~tree).any():
        padded = np.pad(free, 1)
        beside = padded[:-2, 1:-1].astype(np.int8) + padded[2:, 1:-1] + padded[1:-1, :-2] + padded[1:-1, 2:]
        cost = jitter + _BESIDE_PENALTY * beside
        path = _cheapest_path(tree, free, cost)
        for cell in path:
            free[cell] = True
        reached = set()
        for row, col in path:
            for dr, dc in _STEPS:
                if region[row + dr, col + dc] >= 0:
                    reached.add(int(region[row + dr, col + dc]))
        if not path:
            raise RuntimeError("maze generator bug: empty corridor")
        tree[tuple(np.array(path).T)] = True
        for label in reached:
            tree |= region == label
        # Corridor blocks of earlier corridors touched by this one belong to the tree already.
    return free


def _geodesic(free: np.ndarray, source: tuple[int, int]) -> np.ndarray:
    """Steps from `source` to every free block (4-connected); -1 where unreachable."""
    dist = np.full(free.shape, -1, dtype=np.int32)
    dist[source] = 0
    frontier = [source]
    while frontier:
        nxt = []
        for row, col in frontier:
            for dr, dc in _STEPS:
                r, c = row + dr, col + dc
                if free[r, c] and dist[r, c] < 0:
                    dist[r, c] = dist[row, col] + 1
                    nxt.append((r, c))
        frontier = nxt
    return dist


def _open_loops(free: np.ndarray, count: int, rng: np.random.Generator) -> None:
    """Open up to `count` doorways: wall blocks between two free blocks in a straight line
    whose walk around is at least _LOOP_MIN_DETOUR blocks, so each one closes a real loop."""
    for _ in range(count):
        inner = free[1:-1, 1:-1]
        up, down = free[:-2, 1:-1], free[2:, 1:-1]
        left, right = free[1:-1, :-2], free[1:-1, 2:]
        doorway = ((left & right) & ~up & ~down) | ((up & down) & ~left & ~right)
        candidates = np.argwhere(~inner & doorway) + 1
        good = []
        for row, col in candidates[rng.permutation(len(candidates))]:
            if free[row, col - 1] and free[row, col + 1]:
                a, b = (row, col - 1), (row, col + 1)
            else:
                a, b = (row - 1, col), (row + 1, col)
            if _geodesic(free, a)[b] >= _LOOP_MIN_DETOUR:
                good.append((row, col))
                break
        if not good:
            return
        free[good[0]] = True


def _fill_pillars(free: np.ndarray) -> None:
    """Free single wall blocks with four free neighbours (1 x 1 pillars, which the samples
    almost never have). Filling one cannot disconnect anything."""
    inner = free[1:-1, 1:-1]
    pillars = ~inner & free[:-2, 1:-1] & free[2:, 1:-1] & free[1:-1, :-2] & free[1:-1, 2:]
    inner |= pillars


def _is_connected(free: np.ndarray) -> bool:
    _, labels = cv2.connectedComponents(free.astype(np.uint8), connectivity=4)
    return bool(free.any()) and len(np.unique(labels[free])) == 1


def generate_block_grid(config: MazeConfig, rng: np.random.Generator) -> tuple[np.ndarray, tuple[int, int]]:
    """Draw one maze as a boolean block grid (True = free) and its start block (row, col)."""
    low, high = config.side_blocks
    n = int(rng.integers(low, high + 1))
    side_m = n * config.block_m
    rooms = max(1, _scaled_count(config.rooms, side_m, rng))
    region = _place_rooms(n, rooms, config, rng)
    free = _connect_regions(region, rng)
    _open_loops(free, _scaled_count((config.extra_loops, config.extra_loops), side_m, rng), rng)
    _fill_pillars(free)
    start_rows, start_cols = np.nonzero(region == 0)
    start = np.zeros_like(free)
    start[int(start_rows.mean()), int(start_cols.mean())] = True
    # A random rotation and flip spread any bias of the layout over all four sides.
    turns = int(rng.integers(4))
    flip = rng.random() < 0.5
    grids = []
    for grid in (free, start):
        grid = np.rot90(grid, turns)
        grids.append(np.ascontiguousarray(grid[:, ::-1] if flip else grid))
    free, start_mask = grids
    if free[0].any() or free[-1].any() or free[:, 0].any() or free[:, -1].any() or not _is_connected(free):
        raise RuntimeError("maze generator bug: free space touches the border ring or is disconnected")
    row, col = np.argwhere(start_mask)[0]
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
