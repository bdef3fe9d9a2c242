"""benchmarks/real_plan_folds.py: the folds split the shipped plans by building, and a fold's
held-out maps are its plans with the import's start poses."""

from __future__ import annotations

import importlib.util
import json
from pathlib import Path

import yaml

from pipeline.world.maps import list_maps, load_map
from pipeline.world.plans import find_plan_sources, import_plans

ROOT = Path(__file__).resolve().parents[1]
SPEC = importlib.util.spec_from_file_location("real_plan_folds", ROOT / "benchmarks" / "real_plan_folds.py")
assert SPEC is not None and SPEC.loader is not None
folds = importlib.util.module_from_spec(SPEC)
SPEC.loader.exec_module(folds)


def building(name: str) -> str:
    """A plan's building: numbers that run on with one footprint (50052748-50 are 43 m long,
    50052751-54 39 m, so two buildings)."""
    number = int(name.split("_")[0])
    groups = {"A": (50010535, 50010536), "B": (50015847, 50015848), "C": (50037764, 50037765)}
    groups |= {"D": (50052748, 50052750), "E": (50052751, 50052754)}
    return next(group for group, (low, high) in groups.items() if low <= number <= high)


def test_the_folds_hold_out_every_shipped_plan_once_and_no_building_in_two():
    shipped = sorted(path.stem for path in (ROOT / "data/real_plans/kth").glob("*.png") if "_rooms" not in path.name)
    held = [name for fold, names in folds.FOLDS.items() if fold != "all" for name in names]
    assert sorted(held) == shipped and len(held) == len(set(held)) == 14
    assert folds.FOLDS["all"] == ()
    buildings = {fold: {building(name) for name in names} for fold, names in folds.FOLDS.items() if names}
    assert not buildings["f1"] & buildings["f2"]
    params = folds.fold_params(folds.FOLDS["f1"], 0.25, ROOT / "data/real_plans/kth")
    assert params["mazes"]["train"]["plans_exclude"] == list(folds.FOLDS["f1"])
    assert params["mazes"]["train"]["plans_share"] == 0.25 and params["protocol"]["node_resolution"] == 1.0


def test_held_out_maps_are_the_plans_with_the_imports_starts(tmp_path):
    plans = tmp_path / "plans"
    source = find_plan_sources(ROOT / "data/real_plans/kth/50052751.png", resolution=0.05)
    import_plans(source, plans, cell_size=0.2, starts=3)
    maps = folds.held_out_maps(plans, ("50052751",), tmp_path / "held", starts_small=3, max_free_m2=3000)
    paths = list_maps(maps)
    assert [path.stem for path in paths] == ["50052751_s0", "50052751_s1", "50052751_s2"]
    starts = json.loads((plans / "manifest.json").read_text())["plans"][0]["starts"]
    for path, (col, row) in zip(paths, starts):
        assert load_map(path).start_cell == (col, row)
        assert yaml.safe_load(path.read_text())["image"] == "50052751.pgm"
    assert list_maps(folds.held_out_maps(plans, ("50052751",), tmp_path / "none", 3, max_free_m2=100)) == []
