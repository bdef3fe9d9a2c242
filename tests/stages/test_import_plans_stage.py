"""The import_plans stage: params.yaml's `plans` section -> data/plans/ (ROS maps, manifest, licence)."""

from __future__ import annotations

import json

import cv2
import numpy as np
import yaml

from pipeline.world.maps import list_maps, load_map
from stages import import_plans


def test_the_stage_writes_the_plans_of_its_source(tmp_path, monkeypatch):
    source = tmp_path / "my_building"
    source.mkdir()
    for k, width in enumerate((120, 160)):
        image = np.zeros((80, width), np.uint8)
        image[8:72, 8 : width - 8] = 255
        image[8:72, 60:63] = 0
        image[30:44, 60:63] = 255  # a 0.7 m door
        cv2.imwrite(str(source / f"floor_{k}.png"), image)
    (source / "LICENSE.txt").write_text("CC-BY 4.0, the lab\n")
    plans = {"source": str(source), "resolution": 0.05, "cell_size": 0.2, "robot_radius_m": 0.2, "starts": 2, "seed": 0}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump({"plans": plans}))
    monkeypatch.chdir(tmp_path)
    import_plans.main("params.yaml")
    out = tmp_path / "data" / "plans"
    assert [p.name for p in list_maps(out)] == ["floor_0.yaml", "floor_1.yaml"]
    manifest = json.loads((out / "manifest.json").read_text())
    assert [p["licence"] for p in manifest["plans"]] == ["CC-BY 4.0, the lab (LICENSE.txt)"] * 2
    assert (out / "LICENSE.txt").is_file() and all(len(p["starts"]) == 2 for p in manifest["plans"])
    assert load_map(out / "floor_1.yaml").cell_size == 0.2
