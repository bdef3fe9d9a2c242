"""Floor plans as a map family: read in every format, brought to 0.2 m keeping doors, deduplicated, written."""

from __future__ import annotations

import json
import re

import cv2
import numpy as np
import pytest

from pipeline.world.map_files import MapError
from pipeline.world.maps import GroundTruthMap, load_map
from pipeline.world.plans import find_plan_sources, import_plans, symmetry_key
from pipeline.world.reachability import reachable_free
from pipeline.world.resample import write_ros_map


def two_room_plan() -> np.ndarray:
    """A 0.05 m plan (row 0 at the top, 255 free): two 4 m rooms, a 0.1 m wall between them at an
    odd phase with a 0.6 m door, and a closed 1 m cupboard apart from both."""
    image = np.zeros((100, 190), np.uint8)
    image[10:90, 10:90] = 255
    image[10:90, 93:180] = 255
    image[10:90, 90:93] = 0
    image[40:52, 90:93] = 255  # the door: 12 pixels, 0.6 m
    image[92:98, 10:30] = 255  # a cupboard no door reaches
    return image


def write_png(path, image):
    assert cv2.imwrite(str(path), image)
    return path


def test_a_plan_keeps_its_door_and_only_its_largest_free_part(tmp_path):
    write_png(tmp_path / "plan.png", two_room_plan())
    report = import_plans(find_plan_sources(tmp_path / "plan.png", resolution=0.05), tmp_path / "out")
    world = load_map(tmp_path / "out" / "plan.yaml")
    assert world.cell_size == pytest.approx(0.2)
    reachable = reachable_free(world.free, world.start_cell, 1.0)  # the 0.2 m robot: 1 cell of 0.2 m
    assert reachable.sum() == world.free_cell_count  # both rooms, through the 0.6 m door; no cupboard
    assert report.plans[0].free_m2 == pytest.approx(world.free_cell_count * 0.04)
    assert 0.9 * 2 * 16 < report.plans[0].free_m2 < 2 * 16 * 1.05
    manifest = json.loads((tmp_path / "out" / "manifest.json").read_text())
    plan = manifest["plans"][0]
    assert plan["name"] == "plan" and plan["source_resolution_m"] == 0.05 and len(plan["starts"]) == 3
    for col, row in plan["starts"]:
        assert world.free[row, col]


def test_rotated_and_flipped_copies_are_dropped_and_formats_agree(tmp_path):
    image = two_room_plan()
    src = tmp_path / "src"
    src.mkdir()
    write_png(src / "a.png", image)
    write_png(src / "b_turned.png", np.rot90(image)[:, ::-1])
    fine = GroundTruthMap(free=(image > 127)[::-1], start_cell=(20, 20), cell_size=0.05, name="c")
    write_ros_map(fine, src / "c.yaml")  # a saved SLAM map of the same plan: its PGM is not a second plan
    np.save(src / "d.npy", np.ascontiguousarray(image[::-1, ::-1] > 127).astype(np.uint8))  # 0/1 grid, turned 180
    (src / "LICENSE").write_text("Plan licence 1.0\nmore text\n")
    report = import_plans(find_plan_sources(src, resolution=0.05), tmp_path / "out")
    assert [p.name for p in report.plans] == ["a"]
    assert sorted(report.duplicates) == [("b_turned", "a"), ("c", "a"), ("d", "a")]
    assert report.plans[0].licence == "Plan licence 1.0 (LICENSE)"
    assert (tmp_path / "out" / "LICENSE").read_text().startswith("Plan licence")


def test_a_mapex_folder_brings_its_rooms(tmp_path):
    folder = tmp_path / "50010535_PLAN1"
    folder.mkdir()
    image = two_room_plan()
    np.save(folder / "occ_map.npy", np.where(image > 127, 254, 0).astype(np.uint8))
    rooms = np.zeros(image.shape, np.int32)
    rooms[10:90, 10:90], rooms[10:90, 93:180], rooms[92:98, 10:30] = 1, 2, 3
    np.save(folder / "valid_space.npy", rooms)
    report = import_plans(find_plan_sources(folder, resolution=0.05), tmp_path / "out")
    assert report.plans[0].name == "50010535_PLAN1" and report.plans[0].rooms == 2  # the cupboard is not kept
    assert symmetry_key(np.rot90(report_source_free(folder)), 0.05) == report.plans[0].key


def report_source_free(folder):
    return find_plan_sources(folder, resolution=0.05)[0].free


@pytest.mark.parametrize(
    "case, message",
    [
        ("empty", "not a readable image (the file is empty)"),
        ("no free", "no free cell"),
        ("no resolution", "no resolution"),
        ("missing image", "map image"),
    ],
)
def test_bad_plans_are_refused_naming_the_file(tmp_path, case, message):
    path = tmp_path / "plan.png"
    if case == "empty":
        path.write_bytes(b"")
    elif case == "no free":
        write_png(path, np.zeros((40, 40), np.uint8))
    elif case == "no resolution":
        write_png(path, two_room_plan())
    else:
        path = tmp_path / "map.yaml"
        path.write_text(
            "image: gone.pgm\nresolution: 0.05\norigin: [0, 0, 0]\noccupied_thresh: 0.65\nfree_thresh: 0.196\n"
        )
    with pytest.raises(MapError, match=re.escape(message)) as error:
        find_plan_sources(path, resolution=None if case == "no resolution" else 0.05)
    assert str(path) in str(error.value)
