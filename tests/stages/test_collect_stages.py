"""The collect_pairs and collect_expert DVC stages on a tiny params.yaml, run in a temporary folder."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import pytest
import yaml

from pipeline.data.expert_episodes import load_expert_episodes
from pipeline.data.pairs import load_pairs
from pipeline.data.shards import MANIFEST, read_manifest, shard_path
from pipeline.prediction.node_image import PAD_SIZES
from pipeline.world.maps import load_map
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import LATTICE_TOLERANCE_M
from stages import collect_expert, collect_pairs

PAIRS = dict(
    seed=5,
    pairs=6,
    pairs_per_shard=3,
    planners=["nearest_frontier", "greedy_utility"],
    snapshot_every=2,
    stop_steps=[3, 12],
    workers=1,
)
EXPERT = dict(
    seed=12,
    episodes=2,
    episodes_per_shard=1,
    planner="expert",
    planner_options={"time_limit_s": 20},
    horizon=4,
    random_starts=True,
    workers=1,
)


def stage_folder(root: Path, maze_dir: Path | None, params: dict[str, Any]) -> None:
    """A working folder as `dvc repro` sees it: params.yaml and data/mazes/train (the generate_mazes output)."""
    (root / "data/mazes").mkdir(parents=True)
    if maze_dir is None:
        (root / "data/mazes/train").mkdir()
    else:
        (root / "data/mazes/train").symlink_to(maze_dir, target_is_directory=True)
    (root / "params.yaml").write_text(yaml.safe_dump({"protocol": {}, "other_stage": {"ignored": True}, **params}))


def folder_state(directory: Path) -> dict[str, tuple[bytes, int]]:
    """Every file's bytes and modification time: equal states mean nothing was rewritten."""
    return {p.name: (p.read_bytes(), p.stat().st_mtime_ns) for p in sorted(directory.iterdir())}


def assert_shards_reused(before: dict[str, tuple[bytes, int]], after: dict[str, tuple[bytes, int]]) -> None:
    """Shards untouched (same bytes, never rewritten); the manifest, always rewritten last, byte for byte the same."""
    assert {k: v for k, v in after.items() if k != MANIFEST} == {k: v for k, v in before.items() if k != MANIFEST}
    assert after[MANIFEST][0] == before[MANIFEST][0]


def test_pairs_stage_writes_shards_manifest_summary_and_preview(generated_maze_dir, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    stage_folder(tmp_path, generated_maze_dir, {"collect_pairs": PAIRS})
    manifest = collect_pairs.main()

    out_dir = tmp_path / "data/pairs"
    assert sorted(p.name for p in out_dir.iterdir()) == [MANIFEST, "shard_00000.npz", "shard_00001.npz"]
    on_disk = read_manifest(out_dir)
    written = {k: v for k, v in manifest.items() if k not in ("code_version", "made_this_run")}  # provenance stays out
    assert on_disk == json.loads(json.dumps(written, default=str))
    assert manifest["made_this_run"] == [0, 1]
    assert [s["pairs"] for s in on_disk["shards"]] == [3, 3] and on_disk["totals"]["pairs"] == 6
    assert [s["bytes"] for s in on_disk["shards"]] == [shard_path(out_dir, k).stat().st_size for k in range(2)]

    grouped = load_pairs([shard_path(out_dir, k) for k in range(2)])
    assert set(grouped) <= set(PAD_SIZES) and sum(len(g["observed"]) for g in grouped.values()) == 6
    for size, group in grouped.items():
        observed, target, valid = group["observed"], group["target"], group["valid"]
        assert observed.shape[1:] == target.shape[1:] == valid.shape[1:] == (size, size) and valid.dtype == bool
        assert set(np.unique(observed)) <= {0, 128, 255} and set(np.unique(target)) <= {0, 255}
        assert (observed[~valid] == 0).all() and (
            target[~valid] == 0
        ).all()  # padding: obstacle in (the map ends), no loss out
        assert (target[observed == 255] == 255).all()  # what was seen free is free in the ground truth
        assert ((observed == 128) & valid).any()  # rollouts stop early: part of each maze is still unknown

    summary = json.loads((tmp_path / "reports/pairs_summary.json").read_text())
    totals = on_disk["totals"]
    assert summary["pairs"] == 6 and summary["shards"] == 2 and summary["rollouts"] == totals["episodes"] >= 2
    assert summary["bytes"] == sum(shard_path(out_dir, k).stat().st_size for k in range(2))
    assert summary["bytes_per_pair"] == round(summary["bytes"] / 6, 1)
    assert summary["pairs_per_minute"] > 0 and summary["code_version"] == manifest["code_version"]

    # The preview holds every pair (there are fewer than six): one row per pair, 6x scale, a 4-pixel border.
    preview = cv2.imread(str(tmp_path / "reports/pairs_preview.png"))
    rows = [size for size, group in grouped.items() for _ in group["observed"]]
    assert preview.shape == (sum(6 * s + 8 for s in rows), max(6 * (2 * s + 2) + 8 for s in rows), 3)


def test_pairs_stage_rerun_reuses_its_shards_and_drops_those_no_longer_asked_for(
    generated_maze_dir, tmp_path, monkeypatch
):
    """A resumed `dvc repro` must not redo finished shards, nor change a byte DVC has hashed."""
    monkeypatch.chdir(tmp_path)
    stage_folder(tmp_path, generated_maze_dir, {"collect_pairs": PAIRS})
    collect_pairs.main()
    out_dir = tmp_path / "data/pairs"
    before = folder_state(out_dir)

    manifest = collect_pairs.main()
    assert manifest["made_this_run"] == []
    assert_shards_reused(before, folder_state(out_dir))
    assert json.loads((tmp_path / "reports/pairs_summary.json").read_text())["pairs_per_minute"] is None  # made nothing

    (tmp_path / "params.yaml").write_text(yaml.safe_dump({"collect_pairs": {**PAIRS, "pairs": 3}}))
    manifest = collect_pairs.main()
    assert manifest["made_this_run"] == [] and manifest["totals"]["pairs"] == 3
    assert sorted(p.name for p in out_dir.iterdir()) == [MANIFEST, "shard_00000.npz"]
    assert folder_state(out_dir)["shard_00000.npz"] == before["shard_00000.npz"]


def test_expert_stage_stores_lattice_episodes_and_a_matching_summary(generated_maze_dir, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    stage_folder(tmp_path, generated_maze_dir, {"collect_expert": EXPERT})
    manifest = collect_expert.main()

    out_dir = tmp_path / "data/expert"
    assert sorted(p.name for p in out_dir.iterdir()) == [MANIFEST, "shard_00000.npz", "shard_00001.npz"]
    assert manifest["made_this_run"] == [0, 1]
    episodes = [e for k in range(2) for e in load_expert_episodes(shard_path(out_dir, k))]
    totals = read_manifest(out_dir)["totals"]
    assert totals["episodes"] == len(episodes) == 2
    assert totals["steps"] == sum(len(e.positions) for e in episodes)

    protocol = Protocol()  # the params' empty protocol section: the defaults
    resolution = protocol.node_resolution
    for episode in episodes:
        ground_truth = load_map(generated_maze_dir / episode.map_name)
        assert (episode.ground_truth == ground_truth.free).all()
        col, row = episode.start_cell
        assert episode.start_cell != ground_truth.start_cell  # random_starts: a random open cell
        assert ground_truth.free[row - 2 : row + 3, col - 2 : col + 3].all()
        positions = episode.positions
        lattice = positions / resolution
        assert np.array_equal(positions[0], [0.0, 0.0])  # world origin is the start cell, a lattice node
        assert np.abs(positions - np.rint(lattice) * resolution).max() <= LATTICE_TOLERANCE_M  # waypoints are nodes
        assert np.abs(np.rint(np.diff(lattice, axis=0))).max() <= 2  # each move stays within the 5 x 5 edge window
        cells = np.rint(positions / protocol.cell_size).astype(int) + np.asarray(episode.start_cell)
        assert episode.ground_truth[cells[:, 1], cells[:, 0]].all()  # the robot only stands on free cells
        assert episode.future_waypoints.shape == (len(positions), 4, 2)
        assert np.array_equal(episode.future_waypoints[:-1, 0], positions[1:])
        assert np.array_equal(episode.future_waypoints[-1], np.repeat(positions[-1:], 4, axis=0))

    summary = json.loads((tmp_path / "reports/expert_summary.json").read_text())
    assert (
        summary["episodes"] == 2 and summary["steps"] == totals["steps"] and summary["complete"] == totals["complete"]
    )
    assert summary["bytes"] == sum(shard_path(out_dir, k).stat().st_size for k in range(2))
    assert summary["bytes_per_step"] == round(summary["bytes"] / summary["steps"], 1)
    assert summary["episodes_per_minute"] > 0
    preview = cv2.imread(str(tmp_path / "reports/expert_episode.png"))
    assert preview.ndim == 3 and min(preview.shape[:2]) > 100

    before = folder_state(out_dir)
    assert collect_expert.main()["made_this_run"] == []
    assert_shards_reused(before, folder_state(out_dir))
    assert json.loads((tmp_path / "reports/expert_summary.json").read_text())["episodes_per_minute"] is None


@pytest.mark.parametrize("stage", [collect_pairs, collect_expert], ids=["pairs", "expert"])
def test_stages_without_training_mazes_stop_with_a_hint(stage, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    stage_folder(tmp_path, None, {"collect_pairs": PAIRS, "collect_expert": EXPERT})
    with pytest.raises(SystemExit, match="no training mazes; run the generate_mazes stage first"):
        stage.main()
    assert not (tmp_path / "reports").exists() and sorted(p.name for p in (tmp_path / "data").iterdir()) == ["mazes"]


def test_expert_episodes_at_the_building_scale_run_on_the_lattice_to_the_end(tmp_path, monkeypatch):
    # Under the door-aware graph a robot may stand on a door node, where the expert has no node:
    # its episodes ended after a few steps. The stage runs them on DARE's lattice.
    from pipeline.world.building_config import BuildingConfig
    from pipeline.world.buildings import generate_building_set

    floors = tmp_path / "floors"
    generate_building_set(BuildingConfig(side_m=24, cell_size=0.2), 2, floors, seed=(3, 0), progress=False)
    monkeypatch.chdir(tmp_path)
    stage_folder(tmp_path, floors, {"collect_expert": {**EXPERT, "planner_options": {"time_limit_s": 5}}})
    params = yaml.safe_load((tmp_path / "params.yaml").read_text())
    params["protocol"] = {"cell_size": 0.2, "node_resolution": 1.0, "sensor_range": 10.0, "done_unknown_cells": 1000}
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    assert Protocol(**params["protocol"]).uses_door_graph
    collect_expert.main()
    totals = read_manifest(tmp_path / "data/expert")["totals"]
    assert totals["complete"] == totals["episodes"] == 2
    for k in range(2):
        for episode in load_expert_episodes(shard_path(tmp_path / "data/expert", k)):
            lattice = episode.positions / 1.0
            assert np.abs(episode.positions - np.rint(lattice)).max() <= LATTICE_TOLERANCE_M  # lattice nodes only
