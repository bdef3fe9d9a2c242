"""The build_observations DVC stage on three real expert episodes and the shipped inpainter, in a temporary folder."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import yaml
from import_graph import ROOT

from pipeline.data.collect import ExpertConfig, collect_expert_shard
from pipeline.data.expert_episodes import ExpertEpisode, load_expert_episodes
from pipeline.data.observations import load_observations
from pipeline.data.shards import MANIFEST, run_shards, shard_path
from pipeline.prediction.global_graph import FEATURE_NAMES
from pipeline.world.maps import list_maps
from pipeline.world.protocol import Protocol
from stages import build_observations

SHIPPED_INPAINTER = ROOT / "pipeline/assets/inpainter.pt"
SECTION = dict(
    max_nodes=64,
    max_neighbors=16,
    threshold=0.5,
    count_threshold=0.5,
    min_component=3,
    inpainter=str(SHIPPED_INPAINTER),
    workers=1,
)
PREDICTED = FEATURE_NAMES.index("is_predicted")


def stage_folder(root: Path, expert_dir: Path | None, section: dict[str, Any]) -> None:
    """A working folder as `dvc repro` sees it: params.yaml and data/expert (the collect_expert output)."""
    (root / "data").mkdir(parents=True)
    if expert_dir is not None:
        (root / "data/expert").symlink_to(expert_dir, target_is_directory=True)
    (root / "params.yaml").write_text(
        yaml.safe_dump({"protocol": {}, "collect_expert": {"ignored": True}, "build_observations": section})
    )


@pytest.fixture(scope="module")
def expert_dir(expert_shard_dir, generated_maze_dir, tmp_path_factory) -> Path:
    """Expert shards of 2 and 1 episodes: episode ids must count on across shards of unequal size."""
    directory = tmp_path_factory.mktemp("expert_2_1")
    config = ExpertConfig(
        maps=tuple(str(p) for p in list_maps(generated_maze_dir)),
        episodes_per_shard=2,
        planner="expert",
        horizon=8,
        seed=4,
        random_starts=True,
    )
    two = tmp_path_factory.mktemp("expert_two")
    run_shards(collect_expert_shard, 1, two, {"config": config}, progress=False)
    shutil.copy(shard_path(two, 0), shard_path(directory, 0))
    shutil.copy(shard_path(expert_shard_dir, 1), shard_path(directory, 1))  # the session's, horizon 8 too
    manifest = {"shards": [{"file": shard_path(directory, k).name, "episodes": n} for k, n in enumerate((2, 1))]}
    (directory / MANIFEST).write_text(json.dumps(manifest))
    return directory


@pytest.fixture(scope="module")
def episodes(expert_dir) -> list[ExpertEpisode]:
    episodes = [e for k in range(2) for e in load_expert_episodes(shard_path(expert_dir, k))]
    assert len(episodes) == 3
    return episodes


@pytest.fixture(scope="module")
def built(expert_dir, tmp_path_factory) -> tuple[Path, dict]:
    """The stage run once (loading the inpainter dominates its cost); returns (its folder, the summary it returned)."""
    root = tmp_path_factory.mktemp("observations")
    stage_folder(root, expert_dir, SECTION)
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(root)
        summary = build_observations.main("params.yaml")
    return root, summary


@pytest.mark.parametrize("variant", ["guide", "dare"])
def test_every_expert_step_becomes_one_padded_observation(built, episodes, variant):
    """Rows follow the episodes step by step, so T_o histories and action chunks line up with the expert."""
    root, _ = built
    arrays, meta = load_observations(root / f"data/observations/{variant}.npz")
    assert meta == {
        "variant": variant,
        "max_nodes": 64,
        "max_neighbors": 16,
        "threshold": 0.5,
        "min_component": 3,
        "count_threshold": 0.5,
        "protocol": Protocol().to_dict(),
    }  # the policy export carries it on
    lengths = [len(e.positions) for e in episodes]
    total = sum(lengths)
    assert np.array_equal(arrays["episode"], np.repeat(np.arange(len(episodes)), lengths))
    assert np.array_equal(arrays["step"], np.concatenate([np.arange(n) for n in lengths]))
    assert arrays["features"].shape == (total, 64, len(FEATURE_NAMES)) and arrays["node_mask"].shape == (total, 64)
    assert arrays["neighbors"].shape == (total, 64, 16) and arrays["actions"].shape == (total, 8, 2)

    # Actions: the expert's next lattice steps in node units; an episode's last step has nowhere left to go.
    resolution = Protocol().node_resolution
    first_steps = np.concatenate([np.rint(np.diff(e.positions, axis=0) / resolution) for e in episodes])
    not_last = np.concatenate([np.arange(n) < n - 1 for n in lengths])
    assert np.array_equal(arrays["actions"][not_last, 0], first_steps)
    assert (arrays["actions"][~not_last] == 0).all() and np.abs(arrays["actions"]).max() <= 2

    # Rows are nearest first: the robot is row 0 at offset (0, 0); padding rows are empty and never neighbours.
    mask, features, neighbors = arrays["node_mask"], arrays["features"].astype(np.float32), arrays["neighbors"]
    assert (arrays["robot"] == 0).all() and (features[:, 0, :2] == 0).all() and mask[:, 0].all()
    assert (features[~mask] == 0).all() and (neighbors[~mask] == -1).all()
    counts = mask.sum(axis=1)
    assert ((neighbors == -1) | (neighbors < counts[:, None, None])).all()


def test_only_the_guide_observations_carry_predicted_nodes(built):
    """dare sees the observed graph alone; guide adds the frozen predictor's nodes."""
    root, _ = built
    guide, _ = load_observations(root / "data/observations/guide.npz")
    dare, _ = load_observations(root / "data/observations/dare.npz")
    assert (dare["features"][..., PREDICTED] == 0).all()
    assert (guide["features"][..., PREDICTED] == 1).any()


def test_summary_reports_the_written_observations(built, episodes):
    root, returned = built
    summary = json.loads((root / "reports/observations_summary.json").read_text())
    assert summary == returned
    assert summary["episodes"] == len(episodes) and summary["inpainter"] == str(SHIPPED_INPAINTER)
    for variant in ("guide", "dare"):
        arrays, _ = load_observations(root / f"data/observations/{variant}.npz")
        mask = arrays["node_mask"]
        assert summary[variant] == {
            "samples": sum(len(e.positions) for e in episodes),
            "nodes_median": float(np.median(mask.sum(axis=1))),
            "predicted_nodes_median": float(
                np.median(arrays["features"][..., PREDICTED].astype(np.float32).sum(axis=1))
            ),
            "truncated_share": float(mask.all(axis=1).mean()),
        }


def test_rerun_is_byte_identical_and_the_threshold_changes_only_guide(built, expert_dir, tmp_path, monkeypatch):
    """DVC hashes the outputs: the same params must give the same bytes; tau is the guide predictor's alone."""
    root, _ = built
    monkeypatch.chdir(tmp_path)
    stage_folder(tmp_path, expert_dir, SECTION)
    build_observations.main("params.yaml")
    for variant in ("guide", "dare"):
        assert (tmp_path / f"data/observations/{variant}.npz").read_bytes() == (
            root / f"data/observations/{variant}.npz"
        ).read_bytes()

    stage_folder(tmp_path / "strict", expert_dir, {**SECTION, "threshold": 0.9})
    monkeypatch.chdir(tmp_path / "strict")
    build_observations.main("params.yaml")
    loaded = {
        name: {
            variant: load_observations(folder / f"data/observations/{variant}.npz")[0] for variant in ("guide", "dare")
        }
        for name, folder in (("tau 0.5", root), ("tau 0.9", tmp_path / "strict"))
    }
    predicted = {
        name: int(sets["guide"]["features"][..., PREDICTED].astype(np.float32).sum()) for name, sets in loaded.items()
    }
    assert predicted["tau 0.9"] < predicted["tau 0.5"]  # a stricter tau keeps fewer predicted nodes
    assert all(
        np.array_equal(loaded["tau 0.5"]["dare"][k], loaded["tau 0.9"]["dare"][k]) for k in loaded["tau 0.5"]["dare"]
    )


def test_count_threshold_changes_the_utilities_not_the_graph_nodes(built, expert_dir, tmp_path, monkeypatch):
    """The count tau feeds the utility boost only: same predicted nodes, larger boosted utilities."""
    root, _ = built
    stage_folder(tmp_path, expert_dir, {**SECTION, "count_threshold": 0.3})
    monkeypatch.chdir(tmp_path)
    build_observations.main("params.yaml")
    base = load_observations(root / "data/observations/guide.npz")[0]
    broad, meta = load_observations(tmp_path / "data/observations/guide.npz")
    assert meta["count_threshold"] == 0.3
    assert np.array_equal(broad["features"][..., PREDICTED], base["features"][..., PREDICTED])
    assert np.array_equal(broad["node_mask"], base["node_mask"])
    utility = FEATURE_NAMES.index("utility")
    # normalised per observation, so compare where it moved rather than by how much
    assert not np.array_equal(broad["features"][..., utility], base["features"][..., utility])


def test_stage_stops_with_a_hint_when_an_input_is_missing(expert_shard_dir, tmp_path, monkeypatch):
    stage_folder(
        tmp_path / "no_inpainter", expert_shard_dir, {**SECTION, "inpainter": None}
    )  # default: models/inpainter
    monkeypatch.chdir(tmp_path / "no_inpainter")
    with pytest.raises(
        SystemExit, match=r"models/inpainter/inpainter.pt: no inpainter export; run the train_inpainter"
    ):
        build_observations.main()
    stage_folder(tmp_path / "no_shards", None, SECTION)
    monkeypatch.chdir(tmp_path / "no_shards")
    with pytest.raises(
        SystemExit, match="data/expert: no finished expert data set .*run the collect_expert stage first"
    ):
        build_observations.main()
    unfinished = tmp_path / "unfinished_collection"  # shards but no manifest: a collection that never finished
    unfinished.mkdir()
    shutil.copy(shard_path(expert_shard_dir, 0), shard_path(unfinished, 0))
    stage_folder(tmp_path / "unfinished", unfinished, SECTION)
    monkeypatch.chdir(tmp_path / "unfinished")
    with pytest.raises(SystemExit, match="no finished expert data set"):
        build_observations.main()
    assert not list(tmp_path.rglob("observations*"))
