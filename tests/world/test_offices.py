"""The office-floor generator: a second map family in the benchmark's maze PNG format."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pipeline.world.maps import load_maze_png
from pipeline.world.offices import OfficeConfig, draw_office, generate_office, generate_office_set


def test_an_office_floor_is_one_open_connected_space_with_a_free_start():
    config = OfficeConfig(side_m=40.0)
    free, start = draw_office(config, np.random.default_rng(3))
    assert free.shape == (100, 100) and not free[:2].any() and not free[:, -2:].any()  # a wall ring
    assert cv2.connectedComponents(free.astype(np.uint8), connectivity=4)[0] == 2  # background + one space
    assert 0.7 < free.mean() < 0.95  # thin walls: mostly open, unlike the mazes' 40 %
    row, col = start
    assert free[row - 4 : row + 5, col - 4 : col + 5].all()


def test_the_start_the_format_names_is_the_one_drawn(tmp_path):
    config = OfficeConfig(side_m=40.0)
    free, (row, col) = draw_office(config, np.random.default_rng([9, 0]))
    path = generate_office_set(config, 1, tmp_path, seed=[9], progress=False)[0]
    loaded = load_maze_png(path)
    assert (loaded.start_cell[1], loaded.start_cell[0]) == (row, col)
    assert np.array_equal(loaded.free, free)


def test_the_same_seed_draws_the_same_floor_and_doors_pass_the_lattice():
    config = OfficeConfig(side_m=40.0)
    assert np.array_equal(generate_office(config, np.random.default_rng(1)), generate_office(config, np.random.default_rng(1)))
    with pytest.raises(ValueError, match="door_m must start at 4.8 m"):
        OfficeConfig(door_m=(1.0, 2.0))
    with pytest.raises(ValueError, match="twice min_room_m"):
        OfficeConfig(min_room_m=12.0, split_above_m=20.0)
