"""Tests of pipeline.mazes: format, reproducibility and the layout rules of the samples."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pipeline.maps import load_maze_png, maze_cells_from_image
from pipeline.mazes import (
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
    config = MazeConfig(side_m=(25.0, 40.0))
    sides = {generate_maze(config, np.random.default_rng(s)).shape[0] // BLOCK * config.block_m for s in range(30)}
    assert sides <= {25.0, 30.0, 35.0, 40.0}
    assert len(sides) > 1
    big = generate_maze(MazeConfig(side_m=(180.0, 180.0)), np.random.default_rng(0))
    assert big.shape == (900, 900)


def test_rooms_exist(mazes):
    for image in mazes:
        n = image.shape[0] // BLOCK
        free = image[::BLOCK, ::BLOCK] > 150
        two_by_two = free[:-1, :-1] & free[1:, :-1] & free[:-1, 1:] & free[1:, 1:]
        assert two_by_two.any()
        assert 0.3 < free.sum() / n**2 < 0.55


def test_config_accepts_yaml_lists():
    config = MazeConfig(side_m=[100, 100], rooms=[3, 7], room_blocks=[2, 3])
    assert config.side_m == (100.0, 100.0) and config.rooms == (3, 7)
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
