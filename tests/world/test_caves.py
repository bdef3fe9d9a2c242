"""The cave generator: a third map family, in the benchmark's maze PNG format."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from pipeline.lattice.graph import LatticeGraph
from pipeline.lattice.spec import LatticeSpec
from pipeline.world.caves import CaveConfig, draw_cave, generate_cave, generate_cave_set, grow_chambers
from pipeline.world.maps import load_maze_png
from pipeline.world.protocol import Protocol


def test_a_cave_is_one_connected_space_inside_a_wall_ring_with_rough_walls():
    config = CaveConfig(side_m=40.0)
    free, start = draw_cave(config, np.random.default_rng(3))
    assert free.shape == (100, 100) and not free[:5].any() and not free[:, -5:].any()  # the border blocks are rock
    assert cv2.connectedComponents(free.astype(np.uint8), connectivity=4)[0] == 2  # background + one space
    assert free[start] and 0.2 < free.mean() < 0.8
    straight = CaveConfig(side_m=40.0, wall_blur_m=0.0, roughness=0.0)
    blocky, _ = draw_cave(straight, np.random.default_rng(3))
    assert np.array_equal(blocky, np.kron(blocky[5::10, 5::10], np.ones((10, 10), bool)))  # no blur: whole blocks
    assert not np.array_equal(free, np.kron(free[5::10, 5::10], np.ones((10, 10), bool)))  # the blur rounds them


def test_the_majority_rule_keeps_one_region_and_more_passes_smooth_it():
    rng_a, rng_b = np.random.default_rng(1), np.random.default_rng(1)
    raw = grow_chambers(CaveConfig(passes=0), rng_a)
    smooth = grow_chambers(CaveConfig(passes=4), rng_b)
    for blocks in (raw, smooth):
        assert cv2.connectedComponents(blocks.astype(np.uint8), connectivity=4)[0] == 2
        assert not blocks[0].any() and not blocks[:, -1].any()

    def edges(blocks: np.ndarray) -> int:  # open-rock block borders: a rough region has many
        return int((blocks[1:] != blocks[:-1]).sum() + (blocks[:, 1:] != blocks[:, :-1]).sum())

    assert edges(smooth) / smooth.sum() < edges(raw) / raw.sum()


def test_every_open_block_holds_a_lattice_node_the_robot_can_stand_on(tmp_path):
    config = CaveConfig(side_m=40.0)
    path = generate_cave_set(config, 1, tmp_path, seed=[9], progress=False)[0]
    free, (row, col) = draw_cave(config, np.random.default_rng([9, 0]))
    cave = load_maze_png(path)
    assert (cave.start_cell[1], cave.start_cell[0]) == (row, col)  # the start the format names is the one drawn
    assert np.array_equal(cave.free, free)
    graph = LatticeGraph(LatticeSpec.for_map(cave, Protocol()))
    nodes = graph.node_cells  # (col, row) of each lattice node, 10 cells apart from the start
    on_free = free[nodes[:, 1], nodes[:, 0]]
    centres = free[5::10, 5::10]  # the block centres: the lattice, since the start is one
    assert on_free.sum() == centres.sum() > 0


def test_the_same_seed_draws_the_same_cave_and_bad_settings_are_refused():
    config = CaveConfig(side_m=40.0)
    assert np.array_equal(
        generate_cave(config, np.random.default_rng(1)), generate_cave(config, np.random.default_rng(1))
    )
    with pytest.raises(ValueError, match="under 4 cells"):
        CaveConfig(cell_size=1.5)
    with pytest.raises(ValueError, match="open_chance and min_open_share"):
        CaveConfig(open_chance=1.0)
    with pytest.raises(ValueError, match=r"no cave with 90% open blocks"):
        draw_cave(CaveConfig(side_m=40.0, min_open_share=0.9), np.random.default_rng(0))
