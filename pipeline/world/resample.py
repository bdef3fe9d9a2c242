"""Coarser copies of fine maps: a 0.05 m SLAM map explored on the benchmark's 0.4 m grid.

Why a user wants this: the protocol's lidar casts 720 rays half a degree apart. With 0.4 m
cells and a 20 m range neighbouring rays never skip a cell; with 0.05 m cells they are 3.5
cells apart at full range, so every scan leaves holes that read as frontier, and each clutter
speck of a SLAM map casts a shadow that does too. The cell counts the planners and models were
fitted with (`done_unknown_cells`, `min_utility`, the sliver gate's counts) also mean 64 times
less area at 0.05 m (docs/cli.md, "Your own maps").

Obstacles smaller than `speck_area` (0.1 m^2: chair legs, scan noise) are erased first;
then a coarse cell is an obstacle when it holds at least `wall_cells` fine obstacle cells.
The default, 1, never erases a wall: two neighbouring coarse free cells hold no obstacle cell,
so no wall can run between them. Walls thicken instead, by up to one coarse cell, and more
where their edges are ragged. A larger `wall_cells` keeps walls thin, but a thin wall that
crosses the blocks obliquely or along their edges leaves fewer cells in each and gets holes.
"""

from __future__ import annotations

import math
from pathlib import Path

import cv2
import numpy as np
import yaml

from pipeline.common.atomic import atomic_file, atomic_write_text
from pipeline.world.map_files import MapError
from pipeline.world.maps import GroundTruthMap
from pipeline.world.reachability import passable_mask
from pipeline.world.sensor import FREE, OCCUPIED

ROS_FREE_VALUE = 254
ROS_OCCUPIED_VALUE = 0
ROS_UNKNOWN_VALUE = 205  # map_saver's grey: neither free nor occupied


def resample_factor(cell_size: float, new_cell_size: float) -> int:
    """How many fine cells make one coarse cell along each axis; ValueError unless a whole number >= 1."""
    if not (math.isfinite(new_cell_size) and new_cell_size > 0):
        raise ValueError(f"cell size must be a positive number of metres, got {new_cell_size}")
    ratio = new_cell_size / cell_size
    factor = round(ratio)
    if factor < 1 or abs(ratio - factor) > 1e-6 * max(1.0, ratio):
        near = sorted({max(1, math.floor(ratio)), max(1, math.ceil(ratio))})
        sizes = " or ".join(f"{k * cell_size:g}" for k in near)
        raise ValueError(
            f"a {new_cell_size:g} m cell is not a whole number of the map's {cell_size:g} m cells; "
            f"use a multiple, e.g. {sizes} m"
        )
    return factor


def resample_free(free: np.ndarray, factor: int, wall_cells: int) -> np.ndarray:
    """Blocks of `factor` x `factor` fine cells -> one coarse cell, an obstacle when it holds at
    least `wall_cells` fine obstacle cells; the partial blocks at the far edges are dropped."""
    rows, cols = free.shape[0] // factor, free.shape[1] // factor
    blocks = free[: rows * factor, : cols * factor].reshape(rows, factor, cols, factor)
    obstacle_cells = factor * factor - blocks.sum(axis=(1, 3))
    return obstacle_cells < wall_cells


def remove_specks(free: np.ndarray, max_cells: int) -> np.ndarray:
    """`free` with every obstacle of at most `max_cells` cells (8-connected) made free: chair legs
    and scan noise, which a coarse cell would otherwise turn into a 0.4 m block."""
    if max_cells <= 0:
        return free
    count, labels, stats, _ = cv2.connectedComponentsWithStats((~free).astype(np.uint8), connectivity=8)
    small = np.zeros(count, dtype=bool)
    small[1:] = stats[1:, cv2.CC_STAT_AREA] <= max_cells
    return free | small[labels]


def keep_doors(fine: np.ndarray, coarse: np.ndarray, factor: int, radius_cells: float) -> np.ndarray:
    """`coarse` with every cell free that holds a fine cell a robot of `radius_cells` (fine cells) may
    stand on (`passable_mask`): the doors the robot fits through stay open however the blocks fall."""
    belief = np.where(fine, FREE, OCCUPIED).astype(np.uint8)
    rows, cols = coarse.shape
    stands = passable_mask(belief, radius_cells)[: rows * factor, : cols * factor]
    return coarse | stands.reshape(rows, factor, cols, factor).any(axis=(1, 3))


def resample_map(
    ground_truth: GroundTruthMap,
    cell_size: float,
    wall_cells: int = 1,
    speck_area: float = 0.1,
    robot_radius_m: float = 0.0,
) -> tuple[GroundTruthMap, float]:
    """(the map at `cell_size`, metres the start moved).

    Obstacles of at most `speck_area` square metres are erased first (`remove_specks`); then a
    coarse cell is an obstacle when it holds at least `wall_cells` fine obstacle cells (default 1:
    any; the module docstring says why), unless, with a `robot_radius_m`, it holds a fine cell the
    robot's centre may stand on (`keep_doors`: no door it fits through is closed). The start moves to
    the nearest free coarse cell when its own is no longer free. MapError when nothing stays free.
    """
    if not (math.isfinite(speck_area) and speck_area >= 0):
        raise ValueError(f"speck area must be a number of square metres >= 0, got {speck_area}")
    factor = resample_factor(ground_truth.cell_size, cell_size)
    if not 1 <= wall_cells <= factor * factor:
        raise ValueError(
            f"wall cells must lie in 1..{factor * factor} (the fine cells of one new cell), got {wall_cells}"
        )
    fine = remove_specks(ground_truth.free, int(speck_area / ground_truth.cell_size**2))
    free = resample_free(fine, factor, wall_cells)
    if robot_radius_m > 0:
        free = keep_doors(fine, free, factor, robot_radius_m / ground_truth.cell_size)
    if not free.any():
        raise MapError(ground_truth.name, f"no cell of {cell_size:g} m stays free")
    col, row = (min(index // factor, size - 1) for index, size in zip(ground_truth.start_cell, free.shape[::-1]))
    moved = 0.0
    if not free[row, col]:
        cells = np.argwhere(free)
        nearest = cells[int(np.argmin(((cells - (row, col)) ** 2).sum(axis=1)))]
        moved = float(np.hypot(nearest[0] - row, nearest[1] - col) * cell_size)
        row, col = int(nearest[0]), int(nearest[1])
    resampled = GroundTruthMap(
        free=free, start_cell=(int(col), int(row)), cell_size=float(cell_size), name=ground_truth.name
    )
    return resampled, moved


def write_ros_map(
    ground_truth: GroundTruthMap, yaml_path: str | Path, origin: tuple[float, float] = (0.0, 0.0)
) -> Path:
    """Write a map_server map (trinary PGM beside its YAML, with a `start` key), as `load_ros_map` reads it."""
    col, row = ground_truth.start_cell
    size = ground_truth.cell_size
    image = np.where(ground_truth.free, ROS_FREE_VALUE, ROS_OCCUPIED_VALUE).astype(np.uint8)
    return write_map_server(
        image, size, origin, (origin[0] + (col + 0.5) * size, origin[1] + (row + 0.5) * size), yaml_path
    )


def write_map_server(
    image: np.ndarray, resolution: float, origin: tuple[float, float], start: tuple[float, float], yaml_path: str | Path
) -> Path:
    """A map_server map from its pixels (rows growing with y, as our grids'; 254 free, 0 occupied,
    205 unknown): the PGM beside `yaml_path` and the YAML with `origin` (the grid's corner) and a
    `start` key, both in map-frame metres. The PGM's path."""
    yaml_path = Path(yaml_path)
    image_path = yaml_path.with_suffix(".pgm")
    with atomic_file(image_path) as tmp:
        if not cv2.imwrite(str(tmp), np.ascontiguousarray(image[::-1])):  # row 0 of the image is the top
            raise OSError(f"{image_path}: cannot write the map image")
    meta = {
        "image": image_path.name,
        "resolution": resolution,
        "origin": [float(origin[0]), float(origin[1]), 0.0],
        "negate": 0,
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
        "mode": "trinary",
        "start": [float(start[0]), float(start[1])],
    }
    atomic_write_text(yaml_path, yaml.safe_dump(meta, sort_keys=False))
    return image_path
