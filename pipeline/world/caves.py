"""Procedural caves in the maze PNG format: a third map family, which no model is fitted on.

Mazes (rooms of solid blocks) and office floors (thin straight walls) are the two families the
sliver gate is fitted on. A cave has neither straight walls nor rooms: its walls are rough
curves and its open space is a web of chambers and passages of uneven width, as in a SLAM map
of a mine or of rubble. That makes it a fair test of how the planners carry over to maps
unlike any they were trained or tuned on.

A cave is grown by a cellular automaton on a grid of lattice-sized blocks: each block starts
open by chance, and a few passes of the 3 x 3 majority rule turn the noise into chambers. The
largest 4-connected open region is kept. Its blocks are drawn at cell resolution with their
edges blurred and cut at a noisy level, which rounds the corners and roughens the walls. Open
blocks keep their centres free, and the start is one of them, so every lattice node of an open
block is free and a lattice robot can reach every chamber.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np

from pipeline.world.map_files import MAX_IMAGE_PIXELS
from pipeline.world.mazes import generate_map_set
from pipeline.world.offices import render_free_map

MAX_ATTEMPTS = 200  # caves drawn before giving up on one with enough open space


@dataclass(frozen=True)
class CaveConfig:
    """What kind of caves to draw; lengths in metres."""

    side_m: float = 100.0
    cell_size: float = 0.4
    block_m: float = 4.0  # the automaton's block: the 4 m node lattice, so open blocks hold lattice nodes
    open_chance: float = 0.52  # the chance a block starts open
    passes: int = 2  # majority-rule passes: more make fewer, rounder chambers
    wall_blur_m: float = 1.2  # how far the blur rounds a block's corners
    roughness: float = 0.1  # spread of the level the blur is cut at: rough walls
    min_open_share: float = 0.3  # the kept region covers at least this share of the blocks

    def __post_init__(self) -> None:
        if not self.cell_size > 0 or not self.side_m >= 20:
            raise ValueError(f"CaveConfig needs cell_size > 0 and side_m >= 20 m, got {self.cell_size}, {self.side_m}")
        if not self.block_cells >= 4:
            raise ValueError(f"CaveConfig.block_m {self.block_m:g} m is under 4 cells of {self.cell_size:g} m")
        if not 0 < self.open_chance < 1 or not 0 < self.min_open_share < 1:
            raise ValueError(
                "CaveConfig.open_chance and min_open_share must be in (0, 1), "
                f"got {self.open_chance}, {self.min_open_share}"
            )
        if not self.passes >= 0 or not self.wall_blur_m >= 0 or not 0 <= self.roughness < 0.5:
            raise ValueError(
                "CaveConfig needs passes >= 0, wall_blur_m >= 0 and roughness in [0, 0.5), "
                f"got {self.passes}, {self.wall_blur_m}, {self.roughness}"
            )
        if (2 * self.blocks * self.block_cells) ** 2 > MAX_IMAGE_PIXELS:
            largest = math.isqrt(MAX_IMAGE_PIXELS) // 2 * self.cell_size
            raise ValueError(
                f"caves of {self.side_m:g} m make an image of more than the map loader reads; "
                f"the largest side at {self.cell_size:g} m cells is {largest:.0f} m"
            )

    @property
    def block_cells(self) -> int:
        return int(round(self.block_m / self.cell_size))

    @property
    def blocks(self) -> int:
        """Blocks along a side (the side is cut down to whole blocks)."""
        return int(self.side_m // self.block_m)


def grow_chambers(config: CaveConfig, rng: np.random.Generator) -> np.ndarray:
    """The open blocks: random blocks, majority-rule passes, the largest 4-connected region, no border."""
    n = config.blocks
    blocks = rng.random((n, n)) < config.open_chance
    for _ in range(config.passes):
        neighbours = cv2.filter2D(
            blocks.astype(np.float32), -1, np.ones((3, 3), np.float32), borderType=cv2.BORDER_CONSTANT
        )
        blocks = neighbours >= 5  # open where most of the 3 x 3 around (the block included) is open
    blocks[[0, -1], :] = False
    blocks[:, [0, -1]] = False
    count, labels = cv2.connectedComponents(blocks.astype(np.uint8), connectivity=4)
    if count < 2:
        return np.zeros_like(blocks)
    sizes = np.bincount(labels.ravel())[1:]
    return labels == 1 + int(np.argmax(sizes))


def draw_cave(config: CaveConfig, rng: np.random.Generator) -> tuple[np.ndarray, tuple[int, int]]:
    """(free cells, start (row, col)): one cave, its free space one 4-connected region."""
    k = config.block_cells
    for _ in range(MAX_ATTEMPTS):
        blocks = grow_chambers(config, rng)
        if blocks.mean() >= config.min_open_share:
            break
    else:
        raise ValueError(
            f"no cave with {config.min_open_share:.0%} open blocks in {MAX_ATTEMPTS} tries: "
            f"raise CaveConfig.open_chance ({config.open_chance})"
        )
    solid = np.kron(blocks, np.ones((k, k), dtype=bool))
    sigma = config.wall_blur_m / config.cell_size
    blurred = cv2.GaussianBlur(solid.astype(np.float32), (0, 0), sigma) if sigma > 0 else solid.astype(np.float32)
    level = 0.5 + config.roughness * (rng.random(solid.shape) - 0.5)
    free = (blurred > level) & (solid | (blurred > 0.5))  # blur rounds corners; never opens more than half a wall
    rows, cols = np.nonzero(blocks)
    pick = rng.integers(rows.size)
    start = (int(rows[pick]) * k + k // 2, int(cols[pick]) * k + k // 2)
    _, labels = cv2.connectedComponents(free.astype(np.uint8), connectivity=4)
    return labels == labels[start], start


def generate_cave(config: CaveConfig, rng: np.random.Generator) -> np.ndarray:
    """Draw one cave as a maze PNG image (127 wall, 195 free, 208 start square)."""
    return render_free_map(*draw_cave(config, rng))


def generate_cave_set(
    config: CaveConfig,
    count: int,
    out_dir: str | Path,
    seed: int | Sequence[int],
    prefix: str = "cave",
    progress: bool = True,
) -> list[Path]:
    """Write `count` caves as `{prefix}_{i:04d}.png`, cave i drawn from default_rng([*seed, i])."""
    return generate_map_set(lambda rng: generate_cave(config, rng), count, out_dir, seed, prefix, progress)
