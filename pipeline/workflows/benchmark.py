"""Benchmark a folder of maps: the episodes (`pipeline.evaluation.benchmark`), their tables, and
one MLflow run per planner."""

from __future__ import annotations

from pathlib import Path
from typing import Callable

import pandas as pd

from pipeline.common.mlflow_store import check_tracking_uri
from pipeline.evaluation.benchmark import DEFAULT_BASELINE, parse_planner_spec, run_benchmark, with_policy_checkpoint
from pipeline.reporting.tracking import log_benchmark
from pipeline.world.maps import MapError, list_maps
from pipeline.world.protocol import Protocol


def benchmark_folder(
    maps: Path,
    planners: list[str],
    protocol: Protocol,
    out: Path,
    *,
    workers: int | None = None,
    seed: int = 0,
    baseline: str | None = None,
    start: tuple[float, float] | None = None,
    checkpoint: Path | None = None,
    tracking_uri: str | None = None,
    experiment: str = "benchmark",
    mlflow: bool = True,
    warn: Callable[[str], None] | None = None,
) -> pd.DataFrame:
    """Every map in `maps` with each planner spec; writes OUT's trajectories, metrics.csv, summary.md
    and run.json, and logs one MLflow run per planner when `mlflow`.

    `baseline`: the label summary.md compares every planner with (None: greedy_utility when it
    runs; "": none). `checkpoint`: a policy for every diffusion planner. The MLflow store is
    checked before any episode runs, not after all of them.
    """
    if mlflow:
        check_tracking_uri(tracking_uri)
    map_paths = list_maps(maps)
    if not map_paths:
        raise MapError(maps, "no maps in this folder (maze .png, .npy or ROS .yaml)")
    specs = with_policy_checkpoint(list(planners), checkpoint)
    labels = [parse_planner_spec(spec).label for spec in specs]
    if baseline is None:
        baseline = DEFAULT_BASELINE if DEFAULT_BASELINE in labels else ""
    elif baseline and baseline not in labels:
        raise ValueError(f"--baseline {baseline!r} is not among the planners' labels: {', '.join(labels)}")
    frame = run_benchmark(map_paths, specs, protocol, out, workers=workers, seed=seed, baseline=baseline or None,
                          start=start, warn=warn)
    if mlflow:
        log_benchmark(frame, out, protocol, maps=str(maps), tracking_uri=tracking_uri, experiment=experiment)
    return frame
