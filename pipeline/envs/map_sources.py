"""Where an environment's maps come from: one file, a folder (one map per reset), or the maze generator.

A source hands out a map with the protocol it runs under (a ROS map brings its own cell size)
and the largest grid it can hand out, which fixes the padded belief image's size. Every map
a file or folder source reads is checked by the project's loaders; a failure is a ValueError
naming the `map` parameter and the file.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.world.map_files import MapError
from pipeline.world.maps import (
    MAZE_FREE_RULE,
    MAZE_START_INDEX,
    MAZE_START_VALUE,
    GroundTruthMap,
    list_maps,
    load_map,
    maze_cells_from_image,
    maze_free_mask,
    validate_grid,
)
from pipeline.world.mazes import MazeConfig, generate_maze
from pipeline.world.protocol import Protocol, protocol_for_map


@dataclass(frozen=True)
class DrawnMap:
    """One episode's map, the protocol it runs under, and a key naming it among the source's maps."""

    ground_truth: GroundTruthMap
    protocol: Protocol
    key: str  # the file it came from; "" for a generated maze (never seen again)


class MapSource(ABC):
    """Hands out the map of each episode."""

    @abstractmethod
    def draw(self, rng: np.random.Generator) -> DrawnMap:
        """The next episode's map; any randomness comes from `rng` (the reset's generator)."""

    @abstractmethod
    def largest_shape(self) -> tuple[int, int]:
        """The largest (rows, cols) any drawn map can have."""


def _load(path: Path, start: tuple[float, float] | None, protocol: Protocol) -> DrawnMap:
    """A map file and its protocol, or ValueError naming the `map` parameter."""
    try:
        ground_truth = load_map(path, start, protocol.cell_size)
        return DrawnMap(ground_truth, protocol_for_map(protocol, ground_truth, path), str(path))
    except MapError as error:
        raise ValueError(f"map: {error}") from None


class FileSource(MapSource):
    """Every episode on the same map file (read once)."""

    def __init__(self, path: Path, start: tuple[float, float] | None, protocol: Protocol):
        self.drawn = _load(path, start, protocol)

    def draw(self, rng: np.random.Generator) -> DrawnMap:
        return self.drawn

    def largest_shape(self) -> tuple[int, int]:
        return self.drawn.ground_truth.shape


class FolderSource(MapSource):
    """Each episode on a map of a folder (`list_maps`), picked by the reset's generator. The maps
    are all read once when the source is made (so a malformed one fails then, not mid-training),
    and the last few picked are kept."""

    KEPT = 16

    def __init__(self, folder: Path, start: tuple[float, float] | None, protocol: Protocol):
        try:
            self.paths = list_maps(folder)
        except MapError as error:
            raise ValueError(f"map: {error}") from None
        if not self.paths:
            raise ValueError(f"map: {folder}: the folder holds no map (maze .png, ROS .yaml or .npy)")
        self.start, self.protocol = start, protocol
        self._kept: dict[int, DrawnMap] = {}
        shapes = [self._read(k).ground_truth.shape for k in range(len(self.paths))]
        self._shape = (max(s[0] for s in shapes), max(s[1] for s in shapes))

    def _read(self, index: int) -> DrawnMap:
        drawn = _load(self.paths[index], self.start, self.protocol)
        if len(self._kept) < self.KEPT:
            self._kept[index] = drawn
        return drawn

    def map_at(self, index: int) -> DrawnMap:
        """The folder's map `index` (in `list_maps` order)."""
        drawn = self._kept.get(index)
        if drawn is None:
            if len(self._kept) >= self.KEPT:
                self._kept.pop(next(iter(self._kept)))
            drawn = self._read(index)
        return drawn

    def draw(self, rng: np.random.Generator) -> DrawnMap:
        return self.map_at(int(rng.integers(len(self.paths))))

    def largest_shape(self) -> tuple[int, int]:
        return self._shape


class MazeSource(MapSource):
    """A new maze of pipeline/world/mazes.py each episode, drawn from a seed the reset's generator
    draws: map `maze_<seed>` is `generate_maze(config, np.random.default_rng(seed))`, the same
    grid `load_maze_png` reads from that maze's PNG."""

    def __init__(self, config: MazeConfig, protocol: Protocol):
        self.config, self.protocol = config, protocol

    def draw(self, rng: np.random.Generator) -> DrawnMap:
        seed = int(rng.integers(2**63))
        image = generate_maze(self.config, np.random.default_rng(seed))
        ground_truth = maze_from_image(image, self.protocol.cell_size, f"maze_{seed}")
        try:
            return DrawnMap(ground_truth, protocol_for_map(self.protocol, ground_truth), "")
        except MapError as error:
            raise ValueError(f"map: generated {error}") from None

    def largest_shape(self) -> tuple[int, int]:
        side = self.config.side_blocks[1] * self.config.block_pixels // 2
        return side, side


def maze_from_image(image: np.ndarray, cell_size: float, name: str) -> GroundTruthMap:
    """The map `load_maze_png` reads from a maze image, without the file: cells are 2x2 pixel
    minima, the start is the 11th start-marker cell in row-major order (docs/protocol.md)."""
    cells = maze_cells_from_image(image)
    rows, cols = np.nonzero(cells == MAZE_START_VALUE)
    if rows.size <= MAZE_START_INDEX:
        raise ValueError(f"map: generated maze {name} has no start marker")
    start = (int(cols[MAZE_START_INDEX]), int(rows[MAZE_START_INDEX]))
    free = maze_free_mask(cells)
    validate_grid(free, start, name, MAZE_FREE_RULE)
    return GroundTruthMap(free=free, start_cell=start, cell_size=cell_size, name=name, free_rule=MAZE_FREE_RULE)


def map_source(
    map_value: str, start: tuple[float, float] | None, protocol: Protocol, maze: MazeConfig | None
) -> MapSource:
    """The source a `map` parameter names: `maze` (with its config), a folder, or a map file."""
    if maze is not None:
        return MazeSource(maze, protocol)
    path = Path(map_value).expanduser()
    if path.is_dir():
        return FolderSource(path, start, protocol)
    if not path.is_file():
        raise ValueError(f"map: {map_value}: no such map file or folder (or pass map='maze' for generated mazes)")
    return FileSource(path, start, protocol)
