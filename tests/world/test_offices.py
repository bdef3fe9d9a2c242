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
    assert np.array_equal(
        generate_office(config, np.random.default_rng(1)), generate_office(config, np.random.default_rng(1))
    )
    with pytest.raises(ValueError, match="lattice_m .* whole number"):
        OfficeConfig(
            door_m=(1.0, 2.0), lattice_m=4.1
        )  # narrow doors go over lattice lines: the lattice must fit the cells
    with pytest.raises(ValueError, match="two cells"):
        OfficeConfig(door_m=(0.2, 2.0))
    with pytest.raises(ValueError, match="twice min_room_m"):
        OfficeConfig(min_room_m=12.0, split_above_m=20.0)


def _lattice_reach(free: np.ndarray, start: tuple[int, int], step: int) -> np.ndarray:
    """Cells of the lattice nodes (spaced `step` from `start`) reachable from the start by straight
    free moves to the four neighbouring nodes."""
    rows, cols = free.shape
    seen = {start}
    todo = [start]
    while todo:
        r, c = todo.pop()
        for dr, dc in ((step, 0), (-step, 0), (0, step), (0, -step)):
            nr, nc = r + dr, c + dc
            if (nr, nc) in seen or not (0 <= nr < rows and 0 <= nc < cols):
                continue
            segment = free[min(r, nr) : max(r, nr) + 1, min(c, nc) : max(c, nc) + 1]
            if segment.all():
                seen.add((nr, nc))
                todo.append((nr, nc))
    reached = np.zeros_like(free)
    for r, c in seen:
        reached[r, c] = True
    return reached


@pytest.mark.parametrize("seed", range(4))
def test_real_robot_floors_have_narrow_doors_a_1_m_lattice_passes(seed):
    config = OfficeConfig.for_scale("real_robot", side_m=30.0, cell_size=0.2)
    assert config.door_m[0] == 0.8 and config.aligns_doors
    free, start = draw_office(config, np.random.default_rng(seed))
    assert free.shape == (150, 150)
    reached = _lattice_reach(free, start, step=5)
    # Every free cell lies within one lattice step of a node the start reaches: no room is closed to the lattice.
    near = cv2.dilate(reached.astype(np.uint8), np.ones((11, 11), np.uint8)).astype(bool)
    assert (free & ~near).sum() == 0


def test_the_maze_scale_floors_are_the_ones_drawn_before_scales_existed():
    assert OfficeConfig.for_scale("maze", 40.0, 0.4) == OfficeConfig(side_m=40.0)
    assert not OfficeConfig().aligns_doors  # no lattice phase is drawn: the same random stream as before
    with pytest.raises(ValueError, match="office scale must be one of"):
        OfficeConfig.for_scale("tiny")


def test_a_set_draws_each_floor_side_from_the_range(tmp_path):
    config = OfficeConfig.for_scale("real_robot", cell_size=0.2)
    paths = generate_office_set(config, 4, tmp_path, seed=[3], progress=False, side_m=(20, 30))
    sides = {load_maze_png(path).free.shape[0] * 0.2 for path in paths}
    assert all(20 <= side <= 30 for side in sides) and len(sides) > 1
    with pytest.raises(ValueError, match="at least 20 m"):
        generate_office_set(config, 1, tmp_path / "x", seed=[3], progress=False, side_m=(10, 30))
