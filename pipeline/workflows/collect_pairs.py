"""Stage I data (the `collect_pairs` stage): (observed, ground-truth) node-image pairs from rollouts of a mix of
planners, with random early stopping, in the training mazes; written as shards, with a summary and a preview.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated, cast

import cv2
import numpy as np

from pipeline.common.atomic import atomic_file, atomic_write_json
from pipeline.common.config import Section, list_of, pair, satisfies, whole
from pipeline.common.paths import CHECKPOINTS, DATA, REPORTS
from pipeline.data.collect import PAIRS_SOURCES, PairsConfig, collect_pairs_shard
from pipeline.data.pairs import load_pairs
from pipeline.data.shards import rate_per_minute, run_shards, shard_count_for, shard_path
from pipeline.planners import planner_config
from pipeline.workflows.stage_inputs import generated_maps
from pipeline.world.protocol import Protocol

TRAIN_MAZES = DATA.mazes_train
OUT_DIR = DATA.pairs
SUMMARY = REPORTS.pairs
PREVIEW = REPORTS.pairs_preview


class Settings(Section):
    """The `collect_pairs` section of params.yaml."""

    seed: Annotated[int, whole(0)]
    pairs: Annotated[int, whole(1)]
    pairs_per_shard: Annotated[int, whole(1)]
    planners: Annotated[
        list[str], list_of(satisfies(planner_config, "a registered planner name", str))
    ]  # each rollout builds one by name
    snapshot_every: Annotated[int, whole(1, note="steps")]
    stop_steps: Annotated[list[int], pair(whole(1, note="steps"))]
    workers: Annotated[int, whole(0, note="0 or 1: in this process")]


def pairs_preview(out_dir: Path, shard_count: int, path: Path, count: int = 6, scale: int = 6) -> None:
    """Rows of (observed, ground truth) node images, unknown pixels tinted, for a quick look."""
    grouped = load_pairs([shard_path(out_dir, k) for k in range(min(shard_count, 2))])
    samples = [
        (size, observed, target, valid)
        for size, group in sorted(grouped.items())
        for observed, target, valid in zip(group["observed"], group["target"], group["valid"])
    ]
    tiles = []
    for index in np.linspace(0, len(samples) - 1, min(count, len(samples))).astype(int):
        size, observed, target, valid = samples[index]
        obs = cv2.cvtColor(observed, cv2.COLOR_GRAY2BGR)
        obs[(observed == 128) & valid] = (200, 150, 90)
        tgt = cv2.cvtColor(target, cv2.COLOR_GRAY2BGR)
        tgt[~valid] = (60, 60, 60)
        pair = np.concatenate([obs, np.full((size, 2, 3), 255, np.uint8), tgt], axis=1)
        pair = cv2.resize(pair, None, fx=scale, fy=scale, interpolation=cv2.INTER_NEAREST)
        tiles.append(cv2.copyMakeBorder(pair, 4, 4, 4, 4, cv2.BORDER_CONSTANT, value=(255, 255, 255)))
    width = max(t.shape[1] for t in tiles)
    rows = [
        cv2.copyMakeBorder(t, 0, 0, 0, width - t.shape[1], cv2.BORDER_CONSTANT, value=(255, 255, 255)) for t in tiles
    ]
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:
        cv2.imwrite(str(tmp), np.concatenate(rows, axis=0))


def collect_pairs(settings: Settings, protocol: Protocol, backend: str | None = None):
    """The Stage I pair shards from the `collect_pairs` settings, a summary and a preview; the summary."""
    maps = tuple(str(p) for p in generated_maps(TRAIN_MAZES, "training mazes"))
    shard_count = shard_count_for(settings.pairs, settings.pairs_per_shard, "pairs")
    config = PairsConfig(
        maps=maps,
        pairs_per_shard=settings.pairs_per_shard,
        planners=tuple(settings.planners),
        snapshot_every=settings.snapshot_every,
        stop_steps=cast(tuple[int, int], tuple(settings.stop_steps)),
        seed=settings.seed,
        protocol=protocol,
    )
    started = time.perf_counter()
    manifest = run_shards(
        collect_pairs_shard,
        shard_count,
        OUT_DIR,
        {"config": config},
        workers=settings.workers,
        backend=backend,
        description="pair shards",
        sources=PAIRS_SOURCES,
        work_dir=CHECKPOINTS.pairs,
    )
    seconds = time.perf_counter() - started
    pairs_preview(OUT_DIR, shard_count, PREVIEW)
    totals = manifest["totals"]
    summary = {
        "pairs": totals["pairs"],
        "rollouts": totals["episodes"],
        "shards": shard_count,
        "bytes": totals["bytes"],
        "bytes_per_pair": round(totals["bytes"] / max(1, totals["pairs"]), 1),
        "seconds": round(seconds, 1),
        # Rate over the shards made by this run (a resumed run reuses finished shards).
        "pairs_per_minute": rate_per_minute(manifest, "pairs", seconds),
        "code_version": manifest["code_version"],  # provenance here, not in the data folder
    }
    atomic_write_json(SUMMARY, summary)
    print(
        f"{manifest['totals']['pairs']} pairs from {manifest['totals']['episodes']} rollouts in {shard_count} shards -> {OUT_DIR}"
    )
    return manifest
