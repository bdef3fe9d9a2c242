"""Tests of the generate_mazes DVC stage on a tiny params.yaml."""

from __future__ import annotations

import cv2
import yaml

from pipeline.maps import load_maze_png
from stages.generate_mazes import main

PARAMS = {
    "protocol": {"cell_size": 0.4},
    "mazes": {
        "seed": 5,
        "block_m": 5.0,
        "rooms": [1, 2],
        "room_blocks": [2, 3],
        "extra_loops": 2,
        "train": {"count": 2, "side_m": [40, 50]},
        "test": {"count": 1, "side_m": [40, 40]},
    },
    "benchmark": {"ignored": True},
}


def _write_params(path, params) -> None:
    path.write_text(yaml.safe_dump(params))


def test_stage_writes_mazes_and_preview(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    _write_params(tmp_path / "params.yaml", PARAMS)
    main()
    train = sorted(p.name for p in (tmp_path / "data/mazes/train").glob("*.png"))
    test = sorted(p.name for p in (tmp_path / "data/mazes/test").glob("*.png"))
    assert train == ["maze_0000.png", "maze_0001.png"]
    assert test == ["maze_0000.png"]
    for path in (tmp_path / "data/mazes").rglob("*.png"):
        load_maze_png(path)
    assert cv2.imread(str(tmp_path / "reports/mazes_preview.png"), cv2.IMREAD_GRAYSCALE) is not None
    # Train and test use different seed sequences.
    assert (tmp_path / "data/mazes/train/maze_0000.png").read_bytes() != (
        tmp_path / "data/mazes/test/maze_0000.png"
    ).read_bytes()

    # A rerun with fewer mazes leaves no stale files, and is byte-identical.
    first = (tmp_path / "data/mazes/train/maze_0000.png").read_bytes()
    smaller = {**PARAMS, "mazes": {**PARAMS["mazes"], "train": {"count": 1, "side_m": [40, 50]}}}
    _write_params(tmp_path / "params.yaml", smaller)
    main("params.yaml")
    assert sorted(p.name for p in (tmp_path / "data/mazes/train").glob("*.png")) == ["maze_0000.png"]
    assert (tmp_path / "data/mazes/train/maze_0000.png").read_bytes() == first
