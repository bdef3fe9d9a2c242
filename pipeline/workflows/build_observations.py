"""The policy's training inputs (the `build_observations` stage): every expert step replayed with the frozen
inpainter into two graph observations, `guide` (the region-evaluated global graph) and `dare` (the observed
graph only).
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import Annotated

import numpy as np

from pipeline.common.atomic import atomic_write_json
from pipeline.common.config import Section, fraction, maybe, text, whole
from pipeline.common.executor import run_tasks
from pipeline.common.fingerprints import files_digest, source_digest
from pipeline.common.kept_results import KeptResults
from pipeline.common.paths import CHECKPOINTS, DATA, POLICIES, REPORTS
from pipeline.data.observations import concatenate, save_observations, shard_observations
from pipeline.data.shards import MANIFEST, read_manifest
from pipeline.models.defaults import PIPELINE_INPAINTER
from pipeline.prediction.global_graph import FEATURE_NAMES
from pipeline.world.protocol import Protocol

EXPERT_DIR = DATA.expert
SUMMARY = REPORTS.observations


class Settings(Section):
    """The `build_observations` section of params.yaml."""

    max_nodes: Annotated[int, whole(1)]
    max_neighbors: Annotated[int, whole(1)]
    threshold: Annotated[float, fraction("tau of the graph's predicted nodes")]
    count_threshold: Annotated[float, fraction("tau of the nodes the utility boost counts")]
    min_component: Annotated[int, whole(0, note="0 or 1: keep every predicted node")]
    inpainter: Annotated[str | None, maybe(text(note="an inpainter export"), "models/inpainter/inpainter.pt")]
    workers: Annotated[int, whole(0, note="0 or 1: in this process")]


def _shard_observations(task: tuple) -> dict:
    """Observations for every episode of one expert shard (runs in a worker process)."""
    (
        shard,
        first_episode_id,
        protocol_dict,
        inpainter,
        threshold,
        count_threshold,
        min_component,
        max_nodes,
        max_neighbors,
    ) = task
    settings = {
        "threshold": threshold,
        "count_threshold": count_threshold,
        "min_component": min_component,
        "max_nodes": max_nodes,
        "max_neighbors": max_neighbors,
    }
    return shard_observations(shard, first_episode_id, Protocol.from_dict(protocol_dict), inpainter, settings)


def build_observations(settings: Settings, protocol: Protocol):
    """Both variants' graph observations from the `build_observations` settings; the summary."""
    inpainter = Path(settings.inpainter or PIPELINE_INPAINTER)
    if not inpainter.is_file():
        raise SystemExit(f"error: {inpainter}: no inpainter export; run the train_inpainter stage first")
    # The manifest, not a folder listing: it is written last, so a collection that never
    # finished (shards but no manifest) is refused instead of silently used in part.
    if not (EXPERT_DIR / MANIFEST).is_file():
        raise SystemExit(
            f"error: {EXPERT_DIR}: no finished expert data set (no {MANIFEST}); run the collect_expert stage first"
        )
    entries = read_manifest(EXPERT_DIR)["shards"]
    shards = [EXPERT_DIR / entry["file"] for entry in entries]
    if not shards:
        raise SystemExit(f"error: {EXPERT_DIR}: no expert shards; run the collect_expert stage first")
    counts = [int(entry["episodes"]) for entry in entries]
    firsts = np.concatenate([[0], np.cumsum(counts)[:-1]]).astype(int)
    tasks = [
        (
            str(s),
            int(f),
            protocol.to_dict(),
            str(inpainter),
            settings.threshold,
            settings.count_threshold,
            settings.min_component,
            settings.max_nodes,
            settings.max_neighbors,
        )
        for s, f in zip(shards, firsts)
    ]
    started = time.perf_counter()
    workers = max(1, settings.workers)
    identity = {
        "tasks": tasks,
        "expert": files_digest([EXPERT_DIR]),
        "inpainter": files_digest([inpainter]),
        "source": source_digest(),
    }
    results = run_tasks(
        _shard_observations,
        tasks,
        workers,
        "expert shards",
        "shard",
        keep=KeptResults(CHECKPOINTS.observations, identity),
    )
    seconds = time.perf_counter() - started
    summary: dict = {"episodes": int(sum(counts)), "seconds": round(seconds, 1), "inpainter": str(inpainter)}
    for variant in ("guide", "dare"):
        arrays = concatenate(r[variant] for r in results)
        meta = {
            "variant": variant,
            **{k: getattr(settings, k) for k in ("max_nodes", "max_neighbors", "threshold", "min_component")},
            "count_threshold": settings.count_threshold,
            "protocol": protocol.to_dict(),
        }
        save_observations(POLICIES[variant].observations, arrays, meta)
        mask = arrays["node_mask"]
        summary[variant] = {
            "samples": int(len(arrays["episode"])),
            "nodes_median": float(np.median(mask.sum(axis=1))),
            "predicted_nodes_median": float(
                np.median(arrays["features"][..., FEATURE_NAMES.index("is_predicted")].astype(np.float32).sum(axis=1))
            ),
            "truncated_share": float(mask.all(axis=1).mean()),  # steps whose graph filled every padded row
        }
    atomic_write_json(SUMMARY, summary)
    print(
        f"observations: {summary['guide']['samples']} steps of {summary['episodes']} expert episodes in {seconds:.0f} s -> {DATA.observations}/"
    )
    return summary
