import numpy as np
from import_graph import ROOT

from pipeline.data.collect import (
    ExpertConfig,
    PairsConfig,
    collect_expert_shard,
    collect_pairs_shard,
    future_waypoints,
    random_open_start,
)
from pipeline.data.expert_episodes import load_expert_episodes
from pipeline.data.pairs import load_pairs
from pipeline.data.shards import read_manifest, run_shards, shard_path
from pipeline.world.maps import list_maps, load_map
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import Episode


def pairs_config(maze_dir, **overrides):
    values = dict(
        maps=tuple(str(p) for p in list_maps(maze_dir)),
        pairs_per_shard=6,
        planners=("nearest_frontier", "greedy_utility"),
        snapshot_every=2,
        stop_steps=(3, 12),
        seed=5,
    )
    values.update(overrides)
    return PairsConfig(**values)


def test_pairs_shards_are_deterministic_and_well_formed(generated_maze_dir, tmp_path):
    config = pairs_config(generated_maze_dir)
    manifest = run_shards(collect_pairs_shard, 2, tmp_path / "a", {"config": config}, progress=False)
    run_shards(collect_pairs_shard, 2, tmp_path / "b", {"config": config}, workers=2, progress=False)
    assert manifest["totals"]["pairs"] == 12
    for k in range(2):
        assert shard_path(tmp_path / "a", k).read_bytes() == shard_path(tmp_path / "b", k).read_bytes()
    grouped = load_pairs([shard_path(tmp_path / "a", k) for k in range(2)])
    assert sum(len(g["observed"]) for g in grouped.values()) == 12
    for size, group in grouped.items():
        assert group["observed"].shape[1:] == (size, size)
        assert set(np.unique(group["observed"])) <= {0, 128, 255}
        assert set(np.unique(group["target"])) <= {0, 255}
        # What is observed free is free in the ground truth too.
        observed_free = group["observed"] == 255
        assert (group["target"][observed_free] == 255).all()


def test_expert_episodes_rebuild_the_belief_exactly(generated_maze_dir, tmp_path):
    config = ExpertConfig(
        maps=tuple(str(p) for p in list_maps(generated_maze_dir))[:1],
        episodes_per_shard=1,
        planner="nearest_frontier",
        horizon=4,
        seed=1,
    )
    manifest = run_shards(collect_expert_shard, 1, tmp_path / "e", {"config": config}, progress=False)
    assert read_manifest(tmp_path / "e")["totals"]["episodes"] == 1
    (episode,) = load_expert_episodes(shard_path(tmp_path / "e", 0))
    ground_truth = load_map(config.maps[0])
    assert (episode.ground_truth == ground_truth.free).all() and episode.start_cell == ground_truth.start_cell
    assert episode.future_waypoints.shape == (len(episode.positions), 4, 2)
    replayed = Episode(ground_truth, Protocol())
    beliefs = episode.beliefs()
    assert (next(beliefs) == replayed.belief.grid).all()
    for position, belief in zip(episode.positions[1:], beliefs):
        replayed.move(position)
        assert (belief == replayed.belief.grid).all()
    assert manifest["totals"]["steps"] == len(episode.positions)


def test_random_starts_give_distinct_expert_episodes_from_open_cells(generated_maze_dir, tmp_path):
    from dataclasses import replace

    maps = tuple(str(p) for p in list_maps(generated_maze_dir))[:1]
    config = ExpertConfig(
        maps=maps, episodes_per_shard=2, planner="nearest_frontier", horizon=4, seed=3, random_starts=True
    )
    run_shards(collect_expert_shard, 1, tmp_path / "e", {"config": config}, progress=False)
    episodes = load_expert_episodes(shard_path(tmp_path / "e", 0))
    ground_truth = load_map(maps[0])
    starts = {episode.start_cell for episode in episodes}
    assert len(starts) == 2 and ground_truth.start_cell not in starts
    for col, row in starts:
        assert ground_truth.free[row - 2 : row + 3, col - 2 : col + 3].all()  # 0.8 m clear on every side
    for episode in episodes:  # each replays exactly from its own start
        replayed = Episode(replace(ground_truth, start_cell=episode.start_cell), Protocol())
        assert (next(episode.beliefs()) == replayed.belief.grid).all()
    walled = replace(ground_truth, free=np.zeros_like(ground_truth.free))
    assert random_open_start(walled, np.random.default_rng(0)) is walled  # nowhere open: the map as it was


def test_future_waypoints_repeat_the_last():
    trajectory = np.arange(10, dtype=np.float32).reshape(5, 2)
    future = future_waypoints(trajectory, 3)
    assert future.shape == (5, 3, 2)
    assert (future[0] == trajectory[1:4]).all() and (future[-1] == trajectory[-1]).all()


def test_collection_sources_exist_and_are_the_stages_dvc_deps():

    import yaml

    from pipeline.common.fingerprints import source_digest
    from pipeline.data.collect import EXPERT_SOURCES, PAIRS_SOURCES

    root = ROOT
    stages = yaml.safe_load((root / "dvc.yaml").read_text())["stages"]
    for stage, sources in (("collect_pairs", PAIRS_SOURCES), ("collect_expert", EXPERT_SOURCES)):
        assert {f"pipeline/{s}" for s in sources} <= set(stages[stage]["deps"]), stage
        assert all((root / "pipeline" / s).exists() for s in sources)
    # The digest of a subset differs from the whole package's, and is stable.
    assert source_digest(PAIRS_SOURCES) == source_digest(PAIRS_SOURCES) != source_digest()
