"""Tests of pipeline.world.mazes: format, reproducibility and the layout rules of the samples."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pipeline.world.maps import load_maze_png, maze_cells_from_image
from pipeline.world.mazes import (
    FREE_VALUE,
    START_VALUE,
    WALL_VALUE,
    MazeConfig,
    generate_maze,
    generate_maze_set,
    write_maze_png,
)

CONFIG = MazeConfig(side_m=(100.0, 130.0))
BLOCK = CONFIG.block_pixels  # 25


@pytest.fixture(scope="module")
def mazes() -> list[np.ndarray]:
    return [generate_maze(CONFIG, np.random.default_rng([7, i])) for i in range(6)]


def test_same_seed_gives_identical_bytes(tmp_path):
    first = generate_maze_set(CONFIG, 2, tmp_path / "a", seed=11, progress=False)
    second = generate_maze_set(CONFIG, 3, tmp_path / "b", seed=11, progress=False)
    assert [p.name for p in first] == ["maze_0000.png", "maze_0001.png"]
    for a, b in zip(first, second):  # maze i does not depend on count
        assert a.read_bytes() == b.read_bytes()


def test_different_seeds_differ(tmp_path):
    one = generate_maze_set(CONFIG, 1, tmp_path / "a", seed=1, progress=False)[0]
    other = generate_maze_set(CONFIG, 1, tmp_path / "b", seed=2, progress=False)[0]
    split = generate_maze_set(CONFIG, 1, tmp_path / "c", seed=(1, 1), progress=False, prefix="m")[0]
    assert split.name == "m_0000.png"
    assert len({one.read_bytes(), other.read_bytes(), split.read_bytes()}) == 3


def test_png_loads_with_start_on_free_cell(tmp_path, mazes):
    for i, image in enumerate(mazes):
        path = write_maze_png(image, tmp_path / f"maze_{i}.png")
        assert not list(tmp_path.glob("*.tmp"))
        grid = load_maze_png(path)
        col, row = grid.start_cell
        assert grid.free[row, col]
        assert grid.shape == (image.shape[0] // 2, image.shape[1] // 2)
        # The loader's start lies inside the 208 block of the image.
        assert image[2 * row, 2 * col] == START_VALUE


def test_values_blocks_and_border(mazes):
    for image in mazes:
        assert image.dtype == np.uint8
        assert set(np.unique(image).tolist()) == {WALL_VALUE, FREE_VALUE, START_VALUE}
        n = image.shape[0] // BLOCK
        assert image.shape == (n * BLOCK, n * BLOCK)
        blocks = image.reshape(n, BLOCK, n, BLOCK)
        assert (blocks.min(axis=(1, 3)) == blocks.max(axis=(1, 3))).all(), "blocks must be uniform"
        block_values = blocks[:, 0, :, 0]
        assert (block_values == START_VALUE).sum() == 1
        ring = np.concatenate([block_values[0], block_values[-1], block_values[:, 0], block_values[:, -1]])
        assert (ring == WALL_VALUE).all()


def test_free_space_is_one_component_after_reduction(mazes):
    for image in mazes:
        free = (maze_cells_from_image(image) > 150).astype(np.uint8)
        count, _ = cv2.connectedComponents(free, connectivity=4)
        assert count == 2  # background + one free component


def test_side_length_in_range():
    config = MazeConfig(side_m=(25.0, 40.0), room_blocks=(2, 3))  # 4-block rooms need >= 30 m
    sides = {generate_maze(config, np.random.default_rng(s)).shape[0] // BLOCK * config.block_m for s in range(30)}
    assert sides <= {25.0, 30.0, 35.0, 40.0}
    assert len(sides) > 1
    big = generate_maze(MazeConfig(side_m=(180.0, 180.0)), np.random.default_rng(0))
    assert big.shape == (900, 900)


def _blocks(image: np.ndarray) -> np.ndarray:
    """The block grid of a maze image: True where the block is free."""
    return image[::BLOCK, ::BLOCK] > 150


def _room_mask(free: np.ndarray) -> np.ndarray:
    """Free blocks that lie in some 2x2 square of free blocks, i.e. in a room."""
    square = free[:-1, :-1] & free[1:, :-1] & free[:-1, 1:] & free[1:, 1:]
    room = np.zeros_like(free)
    for dr in (0, 1):
        for dc in (0, 1):
            room[dr : dr + square.shape[0], dc : dc + square.shape[1]] |= square
    return room


def _rooms(free: np.ndarray) -> list[tuple[int, int]]:
    """(height, width) of every room; fails unless every room is a filled rectangle."""
    count, labels = cv2.connectedComponents(_room_mask(free).astype(np.uint8), connectivity=4)
    sizes = []
    for label in range(1, count):
        rows, cols = np.nonzero(labels == label)
        height, width = np.ptp(rows) + 1, np.ptp(cols) + 1
        assert rows.size == height * width, "a room is not a rectangle"
        sizes.append((int(height), int(width)))
    return sizes


def _loops(free: np.ndarray) -> int:
    """Independent loops of the free space: wall regions it encloses (8-connected walls)."""
    count, labels = cv2.connectedComponents((~free).astype(np.uint8), connectivity=8)
    return count - 2  # background label and the wall region holding the border ring


def test_layout_is_rooms_joined_by_doors(mazes):
    """Like the samples: rectangular rooms 2-4 blocks a side, one-block doors between
    exactly two rooms, no corridor dead ends, 30-55 % free, the start in a 3x3 room."""
    for image in mazes:
        free = _blocks(image)
        n = free.shape[0]
        assert 0.3 < free.sum() / n**2 < 0.55
        sizes = _rooms(free)
        assert len(sizes) >= 8
        assert all(2 <= side <= 4 for size in sizes for side in size)
        room = _room_mask(free)
        for row, col in np.argwhere(free & ~room):
            left_right = free[row, col - 1] and free[row, col + 1] and not free[row - 1, col] and not free[row + 1, col]
            up_down = free[row - 1, col] and free[row + 1, col] and not free[row, col - 1] and not free[row, col + 1]
            assert left_right or up_down, f"block ({row}, {col}) is neither in a room nor a door"
        start = np.argwhere(image[::BLOCK, ::BLOCK] == START_VALUE)[0]
        assert free[start[0] - 1 : start[0] + 2, start[1] - 1 : start[1] + 2].all()
        side_m = n * CONFIG.block_m
        assert _loops(free) == round(CONFIG.extra_loops * (side_m / 100) ** 2)  # per 100 m x 100 m


def test_room_and_loop_counts_scale_with_area():
    """`rooms` and `extra_loops` are per 100 m x 100 m: a 200 m maze gets four times as many."""
    for side_m, factor in ((100.0, 1), (200.0, 4)):
        sparse = MazeConfig(side_m=(side_m, side_m), rooms=(10, 10))
        assert len(_rooms(_blocks(generate_maze(sparse, np.random.default_rng(3))))) == 10 * factor
        dense = MazeConfig(side_m=(side_m, side_m), rooms=(19, 19), extra_loops=1)
        assert _loops(_blocks(generate_maze(dense, np.random.default_rng(3)))) == factor
    tree = MazeConfig(side_m=(100.0, 100.0), extra_loops=0)
    assert _loops(_blocks(generate_maze(tree, np.random.default_rng(3)))) == 0


def test_full_maze_stops_at_the_rooms_that_fit():
    config = MazeConfig(side_m=(30.0, 30.0), rooms=(400, 400))  # far more than 6 x 6 blocks hold
    free = _blocks(generate_maze(config, np.random.default_rng(0)))
    assert 1 <= len(_rooms(free)) < 10
    tiny = MazeConfig(side_m=(25.0, 25.0), rooms=(0, 0), room_blocks=(2, 3), extra_loops=0)
    free = _blocks(generate_maze(tiny, np.random.default_rng(0)))
    assert _rooms(free) and len(_rooms(free)) == 1  # the start room is always there


def test_config_accepts_yaml_lists():
    config = MazeConfig(side_m=[100, 100], rooms=[3, 7], room_blocks=[2, 3])
    assert config.side_m == (100.0, 100.0) and config.rooms == (3, 7) and config.room_blocks == (2, 3)
    assert config.side_blocks == (20, 20) and config.block_pixels == 25


@pytest.mark.parametrize(
    "kwargs, message",
    [
        ({"side_m": (20.0, 100.0)}, "at least 5 blocks"),
        ({"side_m": (100.0, 50.0)}, "low <= high"),
        ({"side_m": (101.0, 104.0)}, "no whole number"),
        ({"side_m": (100.0, 100.0), "block_m": 5.1}, "whole number of pixels"),
        ({"side_m": (100.0, 100.0), "block_m": 1.0}, "at least 9"),
        ({"side_m": (100.0, 100.0), "block_m": -5.0}, "positive"),
        ({"side_m": (100.0, 100.0), "rooms": (5, 2)}, "rooms"),
        ({"side_m": (100.0, 100.0), "room_blocks": (1, 3)}, "room_blocks"),
        ({"side_m": (25.0, 100.0), "room_blocks": (2, 4)}, "does not fit"),
        ({"side_m": (100.0, 100.0), "extra_loops": -1}, "extra_loops"),
        ({"side_m": (100.0,)}, "pair"),
        ({"side_m": (100.0, 100.0), "rooms": (2.5, 3)}, "whole numbers"),
    ],
)
def test_bad_configs_raise(kwargs, message):
    with pytest.raises(ValueError, match=message):
        MazeConfig(**kwargs)


def test_write_rejects_non_uint8(tmp_path):
    with pytest.raises(ValueError):
        write_maze_png(np.zeros((4, 4), dtype=np.float32), tmp_path / "x.png")
