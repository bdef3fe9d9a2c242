"""Benchmark teams on a folder of maps: the episodes and their tables
(`pipeline.evaluation.team_benchmark`), the figures, and one MLflow run per planner and robot count."""

from __future__ import annotations

from pathlib import Path
from typing import Callable, Sequence

from pipeline.common.mlflow_store import check_tracking_uri
from pipeline.evaluation.benchmark import MapSet, with_policy_checkpoint
from pipeline.evaluation.exploration_curves import SpeedModel
from pipeline.evaluation.team_benchmark import (
    TEAM_COVERAGE_FIGURE,
    TeamBenchmarkRun,
    check_comm_range,
    check_robot_counts,
    run_team_benchmark,
)
from pipeline.planners.specs import PlannerSpec, as_specs
from pipeline.planners.team.registry import team_config
from pipeline.reporting.coverage_figure import team_coverage_figure
from pipeline.reporting.team_figures import team_paths_figure
from pipeline.reporting.tracking import log_team_benchmark
from pipeline.world.protocol import Protocol


def maps_text(count: int) -> str:
    """ "1 map", "12 maps": for figure titles."""
    return f"{count} map{'s' if count != 1 else ''}"


PATHS_SUFFIX = ".team.png"  # beside the first map's team file of each run: its robots' paths


def team_benchmark_folder(
    maps: Path | MapSet,
    planners: Sequence[str | PlannerSpec],
    protocol: Protocol,
    out: Path,
    robots: Sequence[int],
    *,
    comm_range_m: float | None = None,
    workers: int | None = None,
    seed: int = 0,
    start: tuple[float, float] | None = None,
    checkpoint: Path | None = None,
    tracking_uri: str | None = None,
    experiment: str = "benchmark",
    mlflow: bool = True,
    warn: Callable[[str], None] | None = None,
    speed: SpeedModel = SpeedModel(),
    backend: str | None = None,
    keep_dir: Path | None = None,
) -> TeamBenchmarkRun:
    """Every map in `maps` with each planner spec at each robot count; writes the team files
    (`run_team_benchmark`), OUT/team_coverage.png, the first map's paths of each run
    (OUT/<run>/<map>.team.png), and logs one MLflow run per planner and robot count when `mlflow`.

    The robot counts, the range and the MLflow store are checked before any map is read;
    `checkpoint` is a policy for every diffusion planner, as in `benchmark_folder`; `keep_dir`
    keeps the finished episodes (`run_team_benchmark`).
    """
    check_robot_counts(robots)
    check_comm_range(comm_range_m)
    if mlflow:
        check_tracking_uri(tracking_uri)
    map_set = MapSet.of(maps, protocol, start)
    specs = with_policy_checkpoint(as_specs(planners), checkpoint, config_of=team_config)
    run = run_team_benchmark(
        map_set,
        specs,
        protocol,
        out,
        robots,
        comm_range_m,
        workers=workers,
        seed=seed,
        warn=warn,
        speed=speed,
        backend=backend,
        keep_dir=keep_dir,
    )
    draw_team_figures(run, Path(out))
    if mlflow:
        log_team_benchmark(run, out, protocol, tracking_uri=tracking_uri, experiment=experiment)
    return run


def draw_team_figures(run: TeamBenchmarkRun, out: Path) -> list[Path]:
    """OUT/team_coverage.png and, per run, its episode on the first map (by name) drawn beside its
    team file; the paths written."""
    written = []
    if not run.coverage.empty:
        range_text = "" if run.record.get("comm_range_m") is None else f", {run.record['comm_range_m']:g} m range"
        written.append(
            team_coverage_figure(
                run.coverage,
                out / TEAM_COVERAGE_FIGURE,
                title=f"Team coverage on {maps_text(run.frame['map'].nunique())}{range_text}: mean, band one standard deviation",
            )
        )
    first = min(result.map_name for _, result in run.episodes) if run.episodes else None
    for task, result in run.episodes:
        if result.map_name != first:
            continue
        ground_truth, protocol, _ = run.maps[result.map_name]
        status = "complete" if result.complete else "incomplete"
        title = (
            f"map {result.map_name}  |  {task.run_label}  |  makespan {result.makespan_m:.1f} m  |  "
            f"total {result.total_distance_m:.1f} m  |  {status}"
        )
        path = out / task.run_label / f"{result.map_name}{PATHS_SUFFIX}"
        team_paths_figure(ground_truth, result.rows, protocol, path, title)
        written.append(path)
    return written
