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

_NEWEST_BIAS = 0.75  # growing-tree: chance to extend the newest corridor (depth-first) vs a random one
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
    rooms: tuple[int, int] = (3, 7)
    room_blocks: tuple[int, int] = (2, 3)
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


def _carve_corridors(free: np.ndarray, rng: np.random.Generator) -> None:
    """Carve a perfect maze over the odd block positions (growing tree).

    Mostly depth-first (long winding corridors) with some random picks (side branches) gives
    corridor layouts closer to the samples than either alone.
    """
    n = free.shape[0]
    nodes = range(1, n - 1, 2)
    last = nodes[-1]
    start = (int(rng.choice(nodes)), int(rng.choice(nodes)))
    free[start] = True
    active = [start]
    while active:
        index = len(active) - 1 if rng.random() < _NEWEST_BIAS else int(rng.integers(len(active)))
        row, col = active[index]
        options = [
            (row + 2 * dr, col + 2 * dc, dr, dc)
            for dr, dc in _STEPS
            if 1 <= row + 2 * dr <= last and 1 <= col + 2 * dc <= last and not free[row + 2 * dr, col + 2 * dc]
        ]
        if not options:
            active.pop(index)
            continue
        next_row, next_col, dr, dc = options[int(rng.integers(len(options)))]
        free[row + dr, col + dc] = True
        free[next_row, next_col] = True
        active.append((next_row, next_col))


def _carve_rooms(free: np.ndarray, config: MazeConfig, rng: np.random.Generator) -> np.ndarray:
    """Carve rectangular rooms inside the wall ring, preferring rooms that do not touch.

    Every room is at least 2x2 blocks, so it covers a maze node and joins the corridors.
    """
    n = free.shape[0]
    count = int(rng.integers(config.rooms[0], config.rooms[1] + 1))
    taken = np.zeros_like(free)
    for _ in range(count):
        for attempt in range(50):
            height, width = (int(v) for v in rng.integers(config.room_blocks[0], config.room_blocks[1] + 1, size=2))
            top = int(rng.integers(1, n - height))  # rows 1 .. n-1-height, so the room ends by row n-2
            left = int(rng.integers(1, n - width))
            # Keep a one-block margin from other rooms so rooms stay distinct; give up on that late.
            margin = taken[max(top - 1, 0) : top + height + 1, max(left - 1, 0) : left + width + 1]
            if not margin.any() or attempt == 49:
                break
        free[top : top + height, left : left + width] = True
        taken[top : top + height, left : left + width] = True
    return taken


def _prune_dead_ends(free: np.ndarray, keep: np.ndarray, target: int, rng: np.random.Generator) -> None:
    """Wall up dead-end blocks (one free neighbour, not in `keep`) until `target` blocks stay free.

    Removing a block with a single free neighbour never disconnects the rest, so the free
    space stays one component; shrinking all dead ends together in random order shortens
    branches evenly and leaves solid wall regions like those of the samples.
    """
    while free.sum() > target:
        padded = np.pad(free, 1)
        degree = (
            padded[:-2, 1:-1].astype(np.int8) + padded[2:, 1:-1] + padded[1:-1, :-2] + padded[1:-1, 2:]
        )
        dead_ends = np.argwhere(free & ~keep & (degree == 1))
        if dead_ends.size == 0:
            return
        removed = False
        for row, col in dead_ends[rng.permutation(len(dead_ends))]:
            if free.sum() <= target:
                return
            neighbours = sum(
                bool(free[row + dr, col + dc])
                for dr, dc in _STEPS
                if 0 <= row + dr < free.shape[0] and 0 <= col + dc < free.shape[1]
            )
            if neighbours == 1:
                free[row, col] = False
                removed = True
        if not removed:
            return


def _open_loops(free: np.ndarray, count: int, rng: np.random.Generator) -> None:
    """Open up to `count` wall blocks that separate two free blocks in a straight line.

    The free space is already connected, so each opening closes a loop. Walls whose other
    two neighbours are wall are preferred: opening them makes a doorway, not a blob.
    """
    for _ in range(count):
        inner = free[1:-1, 1:-1]
        up, down = free[:-2, 1:-1], free[2:, 1:-1]
        left, right = free[1:-1, :-2], free[1:-1, 2:]
        across = (left & right) | (up & down)
        doorway = ((left & right) & ~up & ~down) | ((up & down) & ~left & ~right)
        candidates = np.argwhere(~inner & doorway)
        if candidates.size == 0:
            candidates = np.argwhere(~inner & across)
        if candidates.size == 0:
            return
        row, col = candidates[int(rng.integers(len(candidates)))] + 1
        free[row, col] = True


def _fill_pillars(free: np.ndarray) -> None:
    """Free single wall blocks with four free neighbours: rooms laid over corridors leave such
    1x1 pillars, which the samples almost never have. Filling one cannot disconnect anything."""
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
    free = np.zeros((n, n), dtype=bool)
    _carve_corridors(free, rng)
    rooms = _carve_rooms(free, config, rng)
    target = int(round(rng.uniform(*config.free_fraction) * n * n))
    _prune_dead_ends(free, rooms, target, rng)
    _open_loops(free, config.extra_loops, rng)
    _fill_pillars(free)
    # With an even side the lattice leaves a spare wall line on the bottom/right; a random
    # rotation and flip spread it (and the layout's biases) over all four sides.
    free = np.rot90(free, int(rng.integers(4)))
    if rng.random() < 0.5:
        free = free[:, ::-1]
    free = np.ascontiguousarray(free)
    if free[0].any() or free[-1].any() or free[:, 0].any() or free[:, -1].any() or not _is_connected(free):
        raise RuntimeError("maze generator bug: free space touches the border ring or is disconnected")
    free_blocks = np.argwhere(free)
    start = free_blocks[int(rng.integers(len(free_blocks)))]
    return free, (int(start[0]), int(start[1]))


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
