"""The building-floor generator: floors drawn like real plans, and the statistics that compare them."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from pipeline.planners import make_planner
from pipeline.world.building_config import FREE_LABEL, OUTSIDE_LABEL, WALL_LABEL, BuildingConfig
from pipeline.world.buildings import draw_building, floor_statistics, generate_building, generate_building_set
from pipeline.world.floor_shape import block_mode_labels, plan_statistics, real_plan_grids
from pipeline.world.maps import load_maze_png
from pipeline.world.offices import OfficeConfig, draw_office
from pipeline.world.protocol import PAPER_REAL_ROBOT
from pipeline.world.reachability import reachable_free
from pipeline.world.simulator import run_episode

KTH = Path(__file__).resolve().parents[2] / "data" / "real_plans" / "kth"


def floors(count: int, side: float = 30.0, seed: int = 4):
    return [draw_building(BuildingConfig(side_m=side), np.random.default_rng([seed, i])) for i in range(count)]


def test_a_floor_is_one_connected_free_space_with_its_start_on_the_lattice():
    for floor in floors(6):
        free = floor.free
        assert cv2.connectedComponents(free.astype(np.uint8), connectivity=4)[0] == 2  # background + one space
        row, col = floor.start
        assert free[row - 4 : row + 5, col - 4 : col + 5].all()
        assert (row % floor.step, col % floor.step) == floor.phase
        assert (floor.labels[[0, -1], :] == OUTSIDE_LABEL).all() and (floor.labels[:, [0, -1]] == OUTSIDE_LABEL).all()


def test_every_free_cell_is_reachable_from_the_start_by_a_robot_of_0_2_m_radius():
    for cell_size, side in ((0.2, 36.0), (0.1, 30.0)):
        for i in range(3):
            floor = draw_building(BuildingConfig(side_m=side, cell_size=cell_size), np.random.default_rng([11, i]))
            reached = reachable_free(floor.free, (floor.start[1], floor.start[0]), 0.2 / cell_size)
            assert np.array_equal(reached, floor.free)


def test_footprints_are_elongated_and_irregular_not_squares():
    stats = [floor_statistics(floor, 0.2) for floor in floors(8, side=36.0)]
    aspects = [s["aspect"] for s in stats]
    shares = [s["free_share"] for s in stats]
    assert max(aspects) >= 1.8 and min(aspects) < max(aspects) - 0.5  # elongated, and not all alike
    assert min(shares) <= 0.75  # some footprints leave much of their box outside (wings, courtyards)
    assert all(0.4 < s < 0.95 for s in shares)


def test_rooms_line_corridors_and_most_open_by_one_door():
    stats = [floor_statistics(floor, 0.2) for floor in floors(6, side=36.0)]
    assert np.median([s["one_door_share"] for s in stats]) > 0.5
    assert 1.0 < np.mean([s["doors_per_room"] for s in stats]) < 2.0
    assert all(0.05 < s["corridor_share"] < 0.35 for s in stats)  # corridors, but mostly rooms
    for floor in floors(3, side=36.0):
        labels = floor.room_labels
        assert labels.shape == floor.labels.shape and (labels[~floor.free] == 0).all()
        assert labels.max() == len(floor.rooms) >= 8
        for room, (top, left, bottom, right) in enumerate(floor.rooms, start=1):
            mask = labels == room
            assert mask[top:bottom, left:right].sum() == mask.sum()  # the rectangle bounds its room


def test_walls_land_on_lattice_nodes_at_any_phase_unlike_the_office_floors():
    stats = [floor_statistics(floor, 0.2) for floor in floors(12)]
    assert 0.15 < np.mean([s["wall_runs_on_nodes"] for s in stats]) < 0.7
    assert all(0.06 < s["nodes_on_walls"] < 0.25 for s in stats)
    # The office floors keep their walls between lattice lines: no wall cell on a node.
    office = OfficeConfig.real_robot(side_m=30.0)
    free, start = draw_office(office, np.random.default_rng(4))
    step = office.cells(office.lattice_m)
    nodes = free[start[0] % step :: step, start[1] % step :: step]
    assert nodes[2:-2, 2:-2].mean() > 0.95


def test_walls_are_thin_and_doors_are_door_wide_anywhere_along_a_wall():
    widths, missed = [], 0
    for floor in floors(3, side=40.0, seed=8):
        for top, left, bottom, right in floor.walls:
            assert min(bottom - top, right - left) <= 3  # 0.1-0.3 m at 0.2 m cells, at any phase
        for top, left, bottom, right in floor.doors:
            assert (floor.labels[top:bottom, left:right] == FREE_LABEL).all()
            through_rows = bottom - top <= right - left  # a door through a wall that runs along the rows
            assert min(bottom - top, right - left) <= 4  # through a wall 1-3 cells thick (4 where two meet)
            widths.append(max(bottom - top, right - left))
            along = range(left, right) if through_rows else range(top, bottom)
            phase = floor.phase[1] if through_rows else floor.phase[0]
            missed += not any((k - phase) % floor.step == 0 for k in along)
    assert min(widths) >= 2 and np.mean(np.array(widths) <= 6) > 0.9  # 0.4-1.2 m; a few lobbies open wide
    assert missed > 0  # doors are not placed over the lattice's lines


def test_drawing_is_deterministic_for_a_seed():
    config = BuildingConfig(side_m=32.0)
    first, again = (draw_building(config, np.random.default_rng([21, 3])) for _ in range(2))
    assert np.array_equal(first.labels, again.labels) and np.array_equal(first.room_labels, again.room_labels)
    assert first.start == again.start and first.doors == again.doors and first.rooms == again.rooms
    other = draw_building(config, np.random.default_rng([21, 4]))
    assert not np.array_equal(first.labels, other.labels)


def two_rooms_on_a_corridor(second_door: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """A 13 x 40-cell plan: rooms A (7 x 18 cells) and B (7 x 19) side by side above a corridor
    (3 x 38), a wall row between them and it with one 4-cell door each; optionally a 3-cell door
    between A and B."""
    free = np.zeros((13, 40), dtype=bool)
    rooms = np.zeros((13, 40), dtype=np.int32)
    free[1:8, 1:19], rooms[1:8, 1:19] = True, 1
    free[1:8, 20:39], rooms[1:8, 20:39] = True, 2
    free[9:12, 1:39] = True  # the corridor
    free[8, 5:9] = free[8, 30:34] = True  # the doors
    if second_door:
        free[3:6, 19] = True
    return free, rooms


def test_plan_statistics_give_the_known_answers_on_a_hand_made_plan():
    free, rooms = two_rooms_on_a_corridor()
    stats = plan_statistics(free, rooms, 0.2)
    assert stats["free_share"] == pytest.approx(381 / 418)  # 126 + 133 + 114 + 8 free cells; box 11 x 38
    assert stats["aspect"] == pytest.approx(38 / 11)
    assert stats["rooms_per_100m2"] == pytest.approx(100 * 2 / (381 * 0.04))
    assert stats["room_m2"] == pytest.approx((126 + 133) / 2 * 0.04)
    assert stats["doors_per_room"] == 1.0 and stats["one_door_share"] == 1.0
    assert stats["door_m"] == pytest.approx(0.8)
    assert stats["corridor_share"] == pytest.approx(122 / 381)  # corridor and door cells
    assert stats["nodes_on_walls"] == pytest.approx(37 / 418)  # the wall row less its doors, the wall between
    free, rooms = two_rooms_on_a_corridor(second_door=True)
    stats = plan_statistics(free, rooms, 0.2)
    assert stats["doors_per_room"] == 2.0 and stats["one_door_share"] == 0.0
    assert stats["door_m"] == pytest.approx(0.7)  # median of 0.8, 0.6, 0.6, 0.8
    unlabelled = plan_statistics(free, None, 0.2)
    assert np.isnan(unlabelled["one_door_share"]) and unlabelled["aspect"] == pytest.approx(38 / 11)


def test_a_long_narrow_labelled_room_counts_as_corridor_not_room():
    free, rooms = two_rooms_on_a_corridor()
    rooms[9:12, 1:39] = 3  # a plan that labels its corridor, as the KTH plans do
    stats = plan_statistics(free, rooms, 0.2)
    assert stats["rooms_per_100m2"] == pytest.approx(100 * 2 / (381 * 0.04))
    assert stats["corridor_share"] == pytest.approx(122 / 381)


def test_room_labels_come_to_coarser_cells_by_block_mode_over_free_cells():
    labels = np.array([[1, 1, 2, 2], [1, 0, 2, 2], [3, 3, 0, 0], [3, 0, 0, 4]])
    free = np.array([[1, 1, 1, 1], [1, 1, 1, 1], [1, 0, 1, 1], [0, 0, 1, 1]], dtype=bool)
    assert block_mode_labels(labels, free, 2).tolist() == [[1, 2], [3, 0]]


def test_a_real_plan_is_measured_at_0_2_m_with_its_labels():
    (plan,) = real_plan_grids(KTH / "50052751.png")
    stats = plan_statistics(plan.free, plan.rooms, 0.2)
    assert plan.rooms.shape == plan.free.shape
    assert 2.5 < stats["aspect"] < 3.5 and 0.6 < stats["free_share"] < 0.9  # a 12.5 m x 39 m bar
    assert 15 < stats["rooms_per_100m2"] * stats["free_m2"] / 100 < 30
    assert 0.5 < stats["one_door_share"] <= 1.0 and 0.05 < stats["corridor_share"] < 0.35


def test_the_png_names_the_start_drawn_and_the_same_seed_draws_the_same_floor(tmp_path):
    config = BuildingConfig(side_m=25.0)
    floor = draw_building(config, np.random.default_rng([9, 0]))
    path = generate_building_set(config, 1, tmp_path, seed=[9], progress=False)[0]
    loaded = load_maze_png(path, cell_size=0.2)
    assert (loaded.start_cell[1], loaded.start_cell[0]) == floor.start
    assert np.array_equal(loaded.free, floor.free)
    drawn = [generate_building(config, np.random.default_rng(1)) for _ in range(2)]
    assert np.array_equal(*drawn)
    sides = [
        load_maze_png(p, cell_size=0.2).free.shape[0] * 0.2
        for p in generate_building_set(config, 4, tmp_path / "sides", seed=[2], progress=False, side_m=(20, 60))
    ]
    assert all(20 <= s <= 60 for s in sides) and len(set(sides)) > 1


def test_bad_settings_are_refused_in_words():
    with pytest.raises(ValueError, match="side_m >= 20"):
        BuildingConfig(side_m=10.0)
    with pytest.raises(ValueError, match="lattice_m .* whole number"):
        BuildingConfig(cell_size=0.4)
    with pytest.raises(ValueError, match="door_m"):
        BuildingConfig(door_m=(1.2, 0.7))
    with pytest.raises(ValueError, match="shape_weights"):
        BuildingConfig(shape_weights=(1.0,))
    with pytest.raises(ValueError, match="at least 20 m"):
        generate_building_set(BuildingConfig(), 1, "unused", seed=[0], side_m=(10, 30))


def test_greedy_completes_a_building_floor_at_the_real_robot_protocol(tmp_path):
    path = generate_building_set(BuildingConfig(side_m=24.0), 1, tmp_path, seed=[3], progress=False)[0]
    world = load_maze_png(path, cell_size=0.2)
    result = run_episode(world, make_planner("greedy_utility"), PAPER_REAL_ROBOT, seed=0)
    assert result.complete and result.motion_violations == 0
    assert WALL_LABEL != FREE_LABEL
