"""Training data: Stage I node-image pairs and Stage II expert episodes, written as shards.

Stage I rolls out a mix of planners with random early stopping, so partial maps of every
stage of exploration appear, and snapshots (observed, ground-truth) node images.
Stage II stores expert episodes as raw state: per step the cells the scan revealed (a
compact, exact diff of the belief), the robot's position and the expert's next T_p
waypoints, plus the ground-truth grid, so that graph observations can be rebuilt later
with any node predictor.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import cv2
import numpy as np

from pipeline.data.shards import ShardJob, shard_path, write_shard
from pipeline.lattice.graph import LatticeGraph
from pipeline.lattice.spec import LatticeSpec
from pipeline.planners import make_planner
from pipeline.prediction.node_image import PAD_SIZES, NodeImagePair, node_image_pair
from pipeline.world.maps import GroundTruthMap, load_map
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import Episode, run_episode

# The library code that determines each data set, as the folders (and files) of the pipeline
# package that its collection runs: the resume fingerprints hash them (never the data), and they are the stages'
# code dependencies in dvc.yaml (a test derives both from the import graph).
COLLECTION_SOURCES = (
    "__init__.py",
    "common",
    "data",
    "lattice",
    "models",
    "planners",
    "prediction",
    "stage_runner.py",
    "world",
)
PAIRS_SOURCES = COLLECTION_SOURCES
EXPERT_SOURCES = COLLECTION_SOURCES


def lattice_graph_for(ground_truth: GroundTruthMap, protocol: Protocol) -> LatticeGraph:
    return LatticeGraph(LatticeSpec.for_map(ground_truth, protocol))


# ----------------------------------------------------------------------------- Stage I
@dataclass(frozen=True)
class PairsConfig:
    """Stage I collection: which mazes, how many pairs, and how rollouts are drawn."""

    maps: tuple[str, ...]
    pairs_per_shard: int
    planners: tuple[str, ...]
    snapshot_every: int = 4
    stop_steps: tuple[int, int] = (5, 200)  # random early stop, inclusive
    seed: int = 0
    protocol: Protocol = Protocol()


def collect_pairs_shard(job: ShardJob) -> dict[str, Any]:
    """Roll out until the shard holds `pairs_per_shard` pairs; write it; return its counts."""
    config: PairsConfig = job.params["config"]
    rng = np.random.default_rng([config.seed, job.index])
    sizes: dict[int, list[NodeImagePair]] = {size: [] for size in PAD_SIZES}
    count = 0
    episodes = 0
    while count < config.pairs_per_shard:
        ground_truth = load_map(rng.choice(config.maps), cell_size=config.protocol.cell_size)
        planner = make_planner(str(rng.choice(config.planners)))
        stop = int(rng.integers(config.stop_steps[0], config.stop_steps[1] + 1))
        graph = lattice_graph_for(ground_truth, config.protocol)
        offset = int(rng.integers(0, config.snapshot_every))
        captured: list = []

        def snapshot(episode: Episode) -> None:
            if episode.steps % config.snapshot_every == offset and len(captured) + count < config.pairs_per_shard:
                captured.append(node_image_pair(graph, episode.belief.grid, ground_truth.free))

        run_episode(
            ground_truth,
            planner,
            replace(config.protocol, max_steps=stop),
            seed=int(rng.integers(1 << 31)),
            on_step=snapshot,
        )
        episodes += 1
        for pair in captured:
            sizes[pair.observed.shape[0]].append(pair)
        count += len(captured)
    arrays: dict[str, np.ndarray] = {}
    for size, pairs in sizes.items():
        if pairs:
            arrays[f"observed_{size}"] = np.stack([p.observed for p in pairs])
            arrays[f"target_{size}"] = np.stack([p.target for p in pairs])
            arrays[f"valid_{size}"] = np.stack([p.valid for p in pairs])
    arrays["summary_pairs"] = np.array(count)
    arrays["summary_episodes"] = np.array(episodes)
    path = shard_path(job.out_dir, job.index)
    write_shard(path, arrays)
    return {"pairs": count, "episodes": episodes, "bytes": path.stat().st_size}


# ----------------------------------------------------------------------------- Stage II
@dataclass(frozen=True)
class ExpertConfig:
    """Stage II collection: expert episodes on training mazes."""

    maps: tuple[str, ...]
    episodes_per_shard: int
    planner: str = "expert"
    planner_options: tuple[tuple[str, Any], ...] = ()  # (option, value) pairs `make_planner` gets
    horizon: int = 8  # T_p future waypoints stored per step
    seed: int = 0
    protocol: Protocol = Protocol()
    random_starts: bool = False  # each episode from a random open cell instead of the map's marked start


def random_open_start(
    ground_truth: GroundTruthMap, rng: np.random.Generator, clearance_m: float = 0.8
) -> GroundTruthMap:
    """The map with its start moved to a random cell whose square of +-`clearance_m` is free.

    The expert is deterministic on a map, so episodes from one marked start repeat each other
    step for step (24 episodes on 8 mazes held about 16 distinct ones); other starts give
    other tours, and the clearance keeps the start off walls, as a marked start room does.
    """
    radius = max(0, int(round(clearance_m / ground_truth.cell_size)))
    kernel = np.ones((2 * radius + 1, 2 * radius + 1), np.uint8)
    open_cells = cv2.erode(ground_truth.free.astype(np.uint8), kernel, borderType=cv2.BORDER_CONSTANT, borderValue=0)
    candidates = np.argwhere(open_cells)
    if not len(candidates):
        return ground_truth
    row, col = candidates[int(rng.integers(len(candidates)))]
    return replace(ground_truth, start_cell=(int(col), int(row)))


def future_waypoints(trajectory: np.ndarray, horizon: int) -> np.ndarray:
    """For each step t, the next `horizon` waypoints after t (the last one repeated at the end)."""
    steps = len(trajectory)
    index = np.arange(steps)[:, None] + np.arange(1, horizon + 1)[None, :]
    return trajectory[np.minimum(index, steps - 1)]


def record_episode(ground_truth: GroundTruthMap, planner, protocol: Protocol, seed: int) -> dict[str, Any]:
    """Run `planner` and keep, per step, the belief diff the step's scan made: the episode's
    result, its (steps, 2) trajectory and the diffs (`change_index`, `change_value`)."""
    previous: dict[str, np.ndarray | None] = {"grid": None}
    change_index: list[np.ndarray] = []
    change_value: list[np.ndarray] = []

    def record(episode: Episode) -> None:
        grid = episode.belief.grid.reshape(-1)
        if previous["grid"] is None:
            changed = np.nonzero(grid != 128)[0]
        else:
            changed = np.nonzero(grid != previous["grid"])[0]
        change_index.append(changed.astype(np.int32))
        change_value.append(grid[changed].copy())
        previous["grid"] = grid.copy()

    result = run_episode(ground_truth, planner, protocol, seed=seed, on_step=record)
    return {
        "result": result,
        "trajectory": np.asarray(result.trajectory, dtype=np.float32),
        "change_index": change_index,
        "change_value": change_value,
    }


def record_expert_episode(ground_truth: GroundTruthMap, config: ExpertConfig, seed: int) -> dict[str, Any]:
    """Run the expert; its labels (`targets`) are its own next T_p waypoints."""
    record = record_episode(
        ground_truth, make_planner(config.planner, **dict(config.planner_options)), config.protocol, seed
    )
    return {**record, "targets": future_waypoints(record["trajectory"], config.horizon)}


def episode_shard_arrays(
    ground_truths: list[GroundTruthMap], map_names: list[str], records: list[dict[str, Any]]
) -> dict[str, np.ndarray]:
    """The arrays of one Stage II shard: per episode its map and diffs, per step the position and
    its label (`future_waypoints`, T_p waypoints), read back by `load_expert_episodes`."""
    grids = [np.packbits(g.free.reshape(-1)) for g in ground_truths]
    step_counts = [len(r["trajectory"]) for r in records]
    change_index = [c for r in records for c in r["change_index"]]
    change_value = [v for r in records for v in r["change_value"]]
    return {
        "map_names": np.array(map_names),
        "map_shapes": np.array([g.shape for g in ground_truths], dtype=np.int32),
        "start_cells": np.array([g.start_cell for g in ground_truths], dtype=np.int32),
        "ground_truth_bits": np.concatenate(grids),
        "ground_truth_bit_lengths": np.array([len(g) for g in grids], dtype=np.int64),
        "step_counts": np.array(step_counts, dtype=np.int32),  # waypoints incl. the start, per episode
        "positions": np.concatenate([r["trajectory"] for r in records]),  # (sum steps, 2) metres
        "future_waypoints": np.concatenate([r["targets"] for r in records]),  # (sum steps, T_p, 2) metres
        "change_counts": np.array([len(c) for c in change_index], dtype=np.int32),  # per step
        "change_index": np.concatenate(change_index) if change_index else np.zeros(0, np.int32),
        "change_value": np.concatenate(change_value) if change_value else np.zeros(0, np.uint8),
        "complete": np.array([r["result"].complete for r in records]),
        "distance_m": np.array([r["result"].distance_m for r in records], dtype=np.float64),
        "summary_episodes": np.array(len(records)),
        "summary_steps": np.array(int(sum(step_counts))),
        "summary_complete": np.array(int(sum(r["result"].complete for r in records))),
    }


def collect_expert_shard(job: ShardJob) -> dict[str, Any]:
    """Write `episodes_per_shard` expert episodes as one shard of raw per-step state."""
    config: ExpertConfig = job.params["config"]
    rng = np.random.default_rng([config.seed, job.index])
    ground_truths, names, records = [], [], []
    for _ in range(config.episodes_per_shard):
        map_path = str(rng.choice(config.maps))
        ground_truth = load_map(map_path, cell_size=config.protocol.cell_size)
        if config.random_starts:
            ground_truth = random_open_start(ground_truth, rng)
        records.append(record_expert_episode(ground_truth, config, seed=int(rng.integers(1 << 31))))
        ground_truths.append(ground_truth)
        names.append(Path(map_path).name)
    arrays = episode_shard_arrays(ground_truths, names, records)
    path = shard_path(job.out_dir, job.index)
    write_shard(path, arrays)
    steps = int(arrays["summary_steps"])
    return {
        "episodes": len(records),
        "steps": steps,
        "complete": int(arrays["summary_complete"]),
        "bytes": path.stat().st_size,
    }
