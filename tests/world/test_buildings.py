"""The building-floor generator: floors drawn like real plans (walls at any phase of the lattice)."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pipeline.world.buildings import (
    FREE_LABEL,
    OUTSIDE_LABEL,
    WALL_LABEL,
    BuildingConfig,
    draw_building,
    floor_statistics,
    generate_building,
    generate_building_set,
    lattice_reachable,
)
from pipeline.world.maps import load_maze_png
from pipeline.world.offices import OfficeConfig, draw_office
from pipeline.world.protocol import PAPER_REAL_ROBOT
from pipeline.world.simulator import run_episode
from pipeline.planners import make_planner


def floors(count: int, side: float = 30.0, seed: int = 4):
    return [draw_building(BuildingConfig(side_m=side), np.random.default_rng([seed, i])) for i in range(count)]


def test_a_floor_is_one_connected_free_space_with_its_start_on_the_lattice():
    for floor in floors(6):
        free = floor.free
        assert cv2.connectedComponents(free.astype(np.uint8), connectivity=4)[0] == 2  # background + one space
        row, col = floor.start
        assert free[row - 4 : row + 5, col - 4 : col + 5].all()
        assert (row % floor.step, col % floor.step) == floor.phase
        assert (floor.labels[[0, -1], :] == OUTSIDE_LABEL).all()  # nothing free on the image's edge


def test_every_room_left_on_the_floor_has_a_node_the_lattice_robot_reaches():
    for floor in floors(6):
        reached = lattice_reachable(floor.free, floor.start, floor.step)
        for top, left, bottom, right in floor.rooms:
            if (floor.labels[top:bottom, left:right] == FREE_LABEL).sum() > 4 * floor.step**2:
                assert reached[top:bottom, left:right].any(), (top, left, bottom, right)


def test_walls_land_on_lattice_nodes_about_one_time_in_five_unlike_the_office_floors():
    stats = [floor_statistics(floor, 0.2) for floor in floors(20)]
    on_nodes = np.mean([s["wall_runs_on_nodes"] for s in stats])
    assert 0.1 < on_nodes < 0.35
    assert all(0.8 <= s["door_m"] <= 1.2 for s in stats)
    assert 0.8 < np.mean([s["free_share"] for s in stats]) < 0.97
    # The office floors keep their walls between lattice lines: no wall cell on a node.
    office = OfficeConfig.real_robot(side_m=30.0)
    free, start = draw_office(office, np.random.default_rng(4))
    step = office.cells(office.lattice_m)
    nodes = free[start[0] % step :: step, start[1] % step :: step]
    interior = nodes[2:-2, 2:-2]
    assert interior.mean() > 0.95


def test_walls_are_thin_and_doors_pass_a_lattice_line():
    floor = floors(1, side=40.0, seed=8)[0]
    for top, left, bottom, right in floor.walls:
        assert min(bottom - top, right - left) <= 2  # 0.1-0.3 m at 0.2 m cells
    lines_row, lines_col = floor.phase
    for top, left, bottom, right in floor.doors:
        across = range(left, right) if bottom - top <= right - left else range(top, bottom)
        phase = lines_col if bottom - top <= right - left else lines_row
        assert any((k - phase) % floor.step == 0 for k in across)


def test_the_png_names_the_start_drawn_and_the_same_seed_draws_the_same_floor(tmp_path):
    config = BuildingConfig(side_m=25.0)
    floor = draw_building(config, np.random.default_rng([9, 0]))
    path = generate_building_set(config, 1, tmp_path, seed=[9], progress=False)[0]
    loaded = load_maze_png(path, cell_size=0.2)
    assert (loaded.start_cell[1], loaded.start_cell[0]) == floor.start
    assert np.array_equal(loaded.free, floor.free)
    assert np.array_equal(generate_building(config, np.random.default_rng(1)), generate_building(config, np.random.default_rng(1)))
    sides = [load_maze_png(p, cell_size=0.2).free.shape[0] * 0.2 for p in
             generate_building_set(config, 4, tmp_path / "sides", seed=[2], progress=False, side_m=(20, 60))]
    assert all(20 <= s <= 60 for s in sides) and len(set(sides)) > 1


def test_bad_settings_are_refused_in_words():
    with pytest.raises(ValueError, match="side_m >= 20"):
        BuildingConfig(side_m=10.0)
    with pytest.raises(ValueError, match="lattice_m .* whole number"):
        BuildingConfig(cell_size=0.4)
    with pytest.raises(ValueError, match="door_m"):
        BuildingConfig(door_m=(1.2, 0.7))
    with pytest.raises(ValueError, match="at least 20 m"):
        generate_building_set(BuildingConfig(), 1, "unused", seed=[0], side_m=(10, 30))


def test_greedy_completes_a_building_floor_at_the_real_robot_protocol(tmp_path):
    path = generate_building_set(BuildingConfig(side_m=24.0), 1, tmp_path, seed=[3], progress=False)[0]
    world = load_maze_png(path, cell_size=0.2)
    result = run_episode(world, make_planner("greedy_utility"), PAPER_REAL_ROBOT, seed=0)
    assert result.complete and result.motion_violations == 0
    assert WALL_LABEL != FREE_LABEL
