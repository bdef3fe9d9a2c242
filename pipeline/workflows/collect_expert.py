"""Stage II data (the `collect_expert` stage): expert episodes on the training mazes, stored as raw per-step
state; written as shards, with a summary and a picture of one episode.
"""

from __future__ import annotations

import time
from pathlib import Path

from pipeline.common.atomic import atomic_write_json
from pipeline.common.paths import CHECKPOINTS, DATA, REPORTS
from pipeline.data.collect import EXPERT_SOURCES, ExpertConfig, collect_expert_shard
from pipeline.data.expert_episodes import load_expert_episodes
from pipeline.data.shards import rate_per_minute, run_shards, shard_count_for, shard_path
from pipeline.reporting.render import render_frame, save_png
from pipeline.workflows.stage_inputs import generated_maps
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol

TRAIN_MAZES = DATA.mazes_train
OUT_DIR = DATA.expert
SUMMARY = REPORTS.expert
PREVIEW = REPORTS.expert_preview


def episode_preview(out_dir: Path, path: Path, cell_size: float) -> None:
    """The first stored episode: its final rebuilt belief and the expert's path."""
    episode = load_expert_episodes(shard_path(out_dir, 0))[0]
    belief = None
    for belief in episode.beliefs():
        pass
    ground_truth = GroundTruthMap(
        free=episode.ground_truth, start_cell=episode.start_cell, cell_size=cell_size, name=episode.map_name
    )
    trajectory = [tuple(map(float, p)) for p in episode.positions]
    image = render_frame(
        ground_truth,
        belief.copy(),
        trajectory,
        title=f"expert episode on {episode.map_name}: {len(trajectory) - 1} steps",
    )
    save_png(image, path)


def collect_expert(section: dict, protocol: Protocol, backend: str | None = None):
    """The expert episode shards from the `collect_expert` settings, a summary and a preview; the summary."""
    maps = tuple(str(p) for p in generated_maps(TRAIN_MAZES, "training mazes"))
    per_shard = int(section["episodes_per_shard"])
    shard_count = shard_count_for(int(section["episodes"]), per_shard, "episodes")
    config = ExpertConfig(
        maps=maps,
        episodes_per_shard=per_shard,
        planner=str(section["planner"]),
        planner_options=tuple(sorted((section.get("planner_options") or {}).items())),
        horizon=int(section["horizon"]),
        seed=int(section["seed"]),
        protocol=protocol,
        random_starts=bool(section["random_starts"]),
    )
    started = time.perf_counter()
    manifest = run_shards(
        collect_expert_shard,
        shard_count,
        OUT_DIR,
        {"config": config},
        workers=int(section["workers"]),
        backend=backend,
        description="expert shards",
        sources=EXPERT_SOURCES,
        work_dir=CHECKPOINTS.expert,
    )
    seconds = time.perf_counter() - started
    episode_preview(OUT_DIR, PREVIEW, protocol.cell_size)
    totals = manifest["totals"]
    summary = {
        "episodes": totals["episodes"],
        "complete": totals["complete"],
        "steps": totals["steps"],
        "bytes": totals["bytes"],
        "bytes_per_step": round(totals["bytes"] / max(1, totals["steps"]), 1),
        "seconds": round(seconds, 1),
        # Rate over the shards made by this run (a resumed run reuses finished shards).
        "episodes_per_minute": rate_per_minute(manifest, "episodes", seconds),
        "code_version": manifest["code_version"],  # provenance here, not in the data folder
    }
    atomic_write_json(SUMMARY, summary)
    print(
        f"{totals['episodes']} expert episodes ({totals['complete']} complete), {totals['steps']} steps, "
        f"{totals['bytes'] / max(1, totals['steps']):.0f} bytes per stored step -> {OUT_DIR}"
    )
    return manifest
