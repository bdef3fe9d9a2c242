"""generate_mazes with `plans_share`: a share of a split's floors drawn from the imported plans."""

from __future__ import annotations

import cv2
import numpy as np
import pytest
import yaml

from pipeline.world.maps import load_maze_png
from pipeline.world.plans import find_plan_sources, import_plans, load_plan_grids
from stages.generate_mazes import main


def plan_image() -> np.ndarray:
    image = np.zeros((200, 320), np.uint8)
    image[10:190, 10:310] = 255
    for col in (80, 160, 240):  # rooms off a corridor, each with a 0.8 m door
        image[10:120, col : col + 3] = 0
        image[120:123, 10:310] = 0
    for col in (40, 120, 200, 280):
        image[120:123, col : col + 16] = 255
    return image


def test_a_share_of_the_training_floors_comes_from_the_plans(tmp_path, monkeypatch):
    source = tmp_path / "plans_src"
    source.mkdir()
    cv2.imwrite(str(source / "wing.png"), plan_image())
    import_plans(find_plan_sources(source, resolution=0.05), tmp_path / "data" / "plans")
    params = {
        "protocol": {"cell_size": 0.2},
        "mazes": {
            "seed": 3,
            "train": {"kind": "building", "count": 4, "side_m": [20, 24], "plans_share": 0.5},
            "test": {"kind": "building", "count": 1, "side_m": [20, 20]},
            "offices": {"count": 0},
        },
    }
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    monkeypatch.chdir(tmp_path)
    main()
    names = sorted(p.name for p in (tmp_path / "data/mazes/train").glob("*.png"))
    assert names == ["building_0000.png", "building_0001.png", "plan_0000.png", "plan_0001.png"]
    floors = [load_maze_png(tmp_path / "data/mazes/train" / name, 0.2) for name in names[2:]]
    for floor in floors:
        assert max(floor.shape) <= 24 / 0.2 + 2 and floor.free[floor.start_cell[1], floor.start_cell[0]]
    assert not np.array_equal(floors[0].free, floors[1].free)  # other windows, turns or flips
    first = (tmp_path / "data/mazes/train/plan_0000.png").read_bytes()
    main()
    assert (tmp_path / "data/mazes/train/plan_0000.png").read_bytes() == first  # seeded: the same floors again


def test_plans_at_another_cell_size_or_none_are_refused(tmp_path, monkeypatch):
    params = {
        "protocol": {"cell_size": 0.2},
        "mazes": {
            "seed": 3,
            "train": {"kind": "building", "count": 2, "side_m": [20, 20], "plans_share": 1.0},
            "test": {"kind": "building", "count": 1, "side_m": [20, 20]},
            "offices": {"count": 0},
        },
    }
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    monkeypatch.chdir(tmp_path)
    with pytest.raises(Exception, match="holds no imported plans"):
        main()
    source = tmp_path / "src"
    source.mkdir()
    cv2.imwrite(str(source / "wing.png"), plan_image())
    import_plans(find_plan_sources(source, resolution=0.05), tmp_path / "data" / "plans", cell_size=0.4)
    with pytest.raises(Exception, match="import the plans at the protocol's cell size"):
        main()


def test_excluded_plans_are_never_drawn_and_a_misspelt_one_is_refused(tmp_path, monkeypatch):
    source = tmp_path / "plans_src"
    source.mkdir()
    cv2.imwrite(str(source / "wing.png"), plan_image())
    solid = np.zeros((200, 320), np.uint8)
    solid[10:190, 10:310] = 255  # one open hall: no wall inside, unlike the wing
    cv2.imwrite(str(source / "hall.png"), solid)
    import_plans(find_plan_sources(source, resolution=0.05), tmp_path / "data" / "plans")
    train = {"kind": "building", "count": 6, "side_m": [20, 24], "plans_share": 1.0, "plans_exclude": ["wing"]}
    params = {
        "protocol": {"cell_size": 0.2},
        "mazes": {
            "seed": 3,
            "train": train,
            "test": {"kind": "building", "count": 1, "side_m": [20, 20]},
            "offices": {"count": 0},
        },
    }
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    monkeypatch.chdir(tmp_path)
    main()
    # Every window is the whole plan (sides of 20 m or more, plans of 16 x 10 m), turned or flipped:
    # its free cells are the hall's count, never the wing's.
    hall_free, wing_free = (int(grid.sum()) for grid in load_plan_grids(tmp_path / "data/plans", 0.2))
    assert hall_free != wing_free
    floors = sorted((tmp_path / "data/mazes/train").glob("plan_*.png"))
    assert len(floors) == 6
    for path in floors:
        assert int(load_maze_png(path, 0.2).free.sum()) == hall_free, f"{path.name} was drawn from the excluded wing"
    train["plans_exclude"] = ["wnig"]
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    with pytest.raises(Exception, match="no plan named wnig"):
        main()
    train["plans_exclude"] = ["wing", "hall"]
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    with pytest.raises(Exception, match="every imported plan is excluded"):
        main()
