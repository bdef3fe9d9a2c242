"""Tests of the generate_mazes DVC stage on a tiny params.yaml."""

from __future__ import annotations

import os
import subprocess
import sys

import cv2
import pytest
import yaml
from import_graph import ROOT

from pipeline.world.maps import load_maze_png
from stages.generate_mazes import main

PARAMS = {
    "protocol": {"cell_size": 0.4},
    "mazes": {
        "seed": 5,
        "block_m": 5.0,
        "rooms": [17, 21],
        "room_blocks": [2, 4],
        "extra_loops": 1,
        "train": {"count": 2, "side_m": [40, 50]},
        "test": {"count": 1, "side_m": [40, 40]},
        "offices": {"count": 2},
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
    offices = sorted((tmp_path / "data/offices/train").glob("*.png"))
    assert [p.name for p in offices] == ["office_0000.png", "office_0001.png"]
    assert load_maze_png(offices[0]).free.shape == (250, 250)  # 100 m floors
    office_preview = cv2.imread(str(tmp_path / "reports/offices_preview.png"), cv2.IMREAD_GRAYSCALE)
    assert office_preview is not None and office_preview.std() > 10
    for path in (tmp_path / "data/mazes").rglob("*.png"):
        load_maze_png(path)
    preview = cv2.imread(str(tmp_path / "reports/mazes_preview.png"), cv2.IMREAD_GRAYSCALE)
    assert preview is not None and min(preview.shape) >= 100 and preview.std() > 10  # an image of mazes, not a blank
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


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"room_blocks": [1, 3]}, "room_blocks"),
        ({"offices": {"count": -1}}, r"mazes\.offices\.count: must be a whole number >= 0"),
        ({"offices": {"count": 2, "side": 50}}, r"mazes\.offices\.side: unknown setting \(known: count\)"),
    ],
)
def test_bad_params_fail_before_any_file_is_written(tmp_path, monkeypatch, change, message):
    monkeypatch.chdir(tmp_path)
    bad = {**PARAMS, "mazes": {**PARAMS["mazes"], **change}}
    _write_params(tmp_path / "params.yaml", bad)
    with pytest.raises(ValueError, match=message):
        main()
    assert not (tmp_path / "data").exists() and not (tmp_path / "reports").exists()


def test_stage_runs_as_a_module(tmp_path):
    """`python -m stages.generate_mazes`, as dvc.yaml runs it, in a directory holding params.yaml."""
    small = {**PARAMS, "mazes": {**PARAMS["mazes"], "train": {"count": 1, "side_m": [40, 40]}}}
    _write_params(tmp_path / "params.yaml", small)
    repo = str(ROOT)  # importable even where the package is not installed
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(filter(None, [repo, os.environ.get("PYTHONPATH")]))}
    command = [sys.executable, "-m", "stages.generate_mazes"]
    subprocess.run(command, cwd=tmp_path, env=env, check=True, capture_output=True)
    assert (tmp_path / "data/mazes/train/maze_0000.png").is_file()
    assert (tmp_path / "reports/mazes_preview.png").is_file()


def _files(root) -> dict[str, bytes]:
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(root.rglob("*.png"))}


def test_a_failure_halfway_leaves_the_previous_map_sets(tmp_path, monkeypatch):
    """The three sets replace theirs only together, once all are drawn: here the office floors fail
    after the mazes are done, and data/ is as the first run left it."""
    import stages.generate_mazes as stage

    monkeypatch.chdir(tmp_path)
    _write_params(tmp_path / "params.yaml", PARAMS)
    main()
    before = _files(tmp_path)
    real = stage.generate_office_set

    def dies_after_one_floor(config, count, out_dir, seed):
        real(config, 1, out_dir, seed=seed, progress=False)
        raise OSError("killed")

    monkeypatch.setattr(stage, "generate_office_set", dies_after_one_floor)
    smaller = {**PARAMS, "mazes": {**PARAMS["mazes"], "train": {"count": 1, "side_m": [40, 50]}}}
    _write_params(tmp_path / "params.yaml", smaller)
    with pytest.raises(OSError, match="killed"):
        main()
    assert _files(tmp_path) == before
    assert not [p for p in tmp_path.rglob(".*")]  # no temporary folder left behind


def test_two_runs_write_identical_bytes(tmp_path, monkeypatch):
    for name in ("a", "b"):
        (tmp_path / name).mkdir()
        monkeypatch.chdir(tmp_path / name)
        _write_params(tmp_path / name / "params.yaml", PARAMS)
        main()
    first, second = _files(tmp_path / "a"), _files(tmp_path / "b")
    assert len(first) == 7 and first == second  # 2 + 1 mazes, 2 office floors, 2 previews
