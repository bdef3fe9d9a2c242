"""Benchmark a folder of maps with single robots or teams: the episodes (`pipeline.evaluation.benchmark`,
`pipeline.evaluation.team_benchmark`), their tables and figures, and one MLflow run per planner (and
robot count); and Table II's runs on the test mazes (the `benchmark` stage), with the metrics DVC
tracks, a distance chart and the first maze's trajectories side by side."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated, Callable, Sequence

from pipeline.common.atomic import atomic_folder, atomic_write_text
from pipeline.common.config import Section, list_of, maybe, positive, satisfies, whole
from pipeline.common.mlflow_store import check_tracking_uri
from pipeline.common.paths import CHECKPOINTS, DATA, REPORTS
from pipeline.evaluation.benchmark import (
    COVERAGE_FIGURE,
    DEFAULT_BASELINE,
    BenchmarkInterrupted,
    BenchmarkRun,
    MapSet,
    raise_planner_errors,
    run_benchmark,
    with_policy_checkpoint,
)
from pipeline.evaluation.exploration_curves import SpeedModel
from pipeline.evaluation.team_benchmark import (
    TEAM_COVERAGE_FIGURE,
    TeamBenchmarkRun,
    check_comm_range,
    check_robot_counts,
    resolve_team_specs,
    run_team_benchmark,
)
from pipeline.planners.specs import PlannerSpec, as_specs, resolve_planner_specs
from pipeline.planners.team.registry import team_config
from pipeline.reporting.benchmark_figures import distance_bar_chart, planner_paths_figure
from pipeline.reporting.benchmark_markdown import write_summary
from pipeline.reporting.coverage_figure import coverage_figure, team_coverage_figure
from pipeline.reporting.team_figures import team_paths_figure
from pipeline.reporting.tracking import exploration_metrics, log_benchmark, log_team_benchmark
from pipeline.workflows.stage_inputs import generated_maps
from pipeline.world.protocol import Protocol


def benchmark_with_summary(
    maps: str | Path | Sequence[str | Path] | MapSet, specs, protocol, out_dir: Path, **options
) -> BenchmarkRun:
    """`run_benchmark`, then summary.md beside its tables: also for the episodes a Ctrl-C left."""
    try:
        run = run_benchmark(maps, specs, protocol, out_dir, **options)
    except BenchmarkInterrupted as stop:
        if stop.run is not None:
            write_summary(stop.run, out_dir)
        raise
    write_summary(run, out_dir)
    return run


def benchmark_folder(
    maps: Path,
    planners: Sequence[str | PlannerSpec],
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
    speed: SpeedModel = SpeedModel(),
    backend: str | None = None,
) -> BenchmarkRun:
    """Every map in `maps` with each planner spec; writes OUT's trajectories and their per-step files,
    metrics.csv, summary.md, exploration.csv, the coverage figure and run.json, and logs one MLflow
    run per planner when `mlflow`.

    `baseline`: the label summary.md compares every planner with (None: greedy_utility when it
    runs; "": none). `checkpoint`: a policy for every diffusion planner. The MLflow store is
    checked before any episode runs, not after all of them. `backend`: the executor's engine
    (process or ray; None: $GUIDE_BACKEND, else process).
    """
    if mlflow:
        check_tracking_uri(tracking_uri)
    map_set = MapSet.of(maps, protocol, start)
    specs = with_policy_checkpoint(as_specs(planners), checkpoint)
    labels = [spec.label for spec in specs]
    if baseline is None:
        baseline = DEFAULT_BASELINE if DEFAULT_BASELINE in labels else ""
    elif baseline and baseline not in labels:
        raise ValueError(f"--baseline {baseline!r} is not among the planners' labels: {', '.join(labels)}")
    run = benchmark_with_summary(
        map_set,
        specs,
        protocol,
        out,
        workers=workers,
        seed=seed,
        baseline=baseline or None,
        warn=warn,
        speed=speed,
        backend=backend,
    )
    draw_coverage(run, out, speed)
    if mlflow:
        log_benchmark(run, out, protocol, tracking_uri=tracking_uri, experiment=experiment)
    return run


def draw_coverage(run: BenchmarkRun, out: Path, speed: SpeedModel) -> Path:
    """OUT/coverage.png from the benchmark's per-step records."""
    return coverage_figure(
        run.records,
        Path(out) / COVERAGE_FIGURE,
        speed,
        title=f"Coverage curves on {maps_text(run.frame['map'].nunique())}: mean, band one standard deviation",
    )


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


# A planner entry as on the command line, parsed once and checked by the registry.
PLANNER_SPEC = satisfies(
    lambda spec: resolve_planner_specs([spec])[0],
    "a planner spec: a registered planner's name or label=name:option=value,...",
    parses=True,
)
# A team planner entry: a coordinated team name, uncoordinated_<name>, or a single planner's name.
TEAM_PLANNER_SPEC = satisfies(
    lambda spec: resolve_team_specs([spec])[0][0],
    "a team planner spec: a planner's name (its coordinated team version where there is "
    "one) or uncoordinated_<name>, with label=...:option=value,... as for planners",
    parses=True,
)


class Settings(Section):
    """The `benchmark` section of params.yaml."""

    planners: Annotated[list[PlannerSpec], list_of(PLANNER_SPEC)]
    seed: Annotated[int, whole(0)]
    workers: Annotated[int | None, maybe(whole(1), "all cores")]
    speed_mps: Annotated[float, positive("metres per second")]
    robots: Annotated[list[int], list_of(whole(1, 8), min_length=0)] = []
    team_planners: Annotated[list[PlannerSpec], list_of(TEAM_PLANNER_SPEC, min_length=0)] = []
    comm_range_m: Annotated[float | None, maybe(positive("metres"), "one shared belief")] = None


TEST_MAZES = DATA.mazes_test
OUT_DIR = REPORTS.benchmark
METRICS_PATH = REPORTS.benchmark_metrics
CHART_PATH = REPORTS.benchmark_chart
FIGURE_PATH = REPORTS.benchmark_figure
TEAMS_DIR = REPORTS.teams
KEPT_EPISODES = CHECKPOINTS.benchmark  # a killed stage's finished episodes, outside the folder DVC deletes
KEPT_TEAM_EPISODES = CHECKPOINTS.teams
TEAMS_METRICS_PATH = REPORTS.teams_metrics


def benchmark_test_mazes(settings: Settings, protocol: Protocol):
    """Every planner of the `benchmark` settings on the test mazes: run, tabulated, charted, logged.

    reports/benchmark/ is built in a temporary folder that replaces it as a whole once every file
    in it is written: a stage killed halfway leaves the previous folder, never a mix of two runs.
    Its finished episodes are kept in checkpoints/ meanwhile, so that the rerun makes only the rest.
    """
    maps = MapSet(tuple(map(str, generated_maps(TEST_MAZES, "test mazes"))), protocol, folder=str(TEST_MAZES))
    speed = SpeedModel(settings.speed_mps)
    with atomic_folder(OUT_DIR) as out_dir:
        run = benchmark_with_summary(
            maps,
            settings.planners,
            protocol,
            out_dir,
            workers=settings.workers,
            seed=settings.seed,
            speed=speed,
            keep_dir=KEPT_EPISODES,
        )
        draw_coverage(run, out_dir, speed)
    # After the folder is in place: reports/benchmark.json's temporary name shares the folder's
    # ".benchmark.partial-" prefix, and a write clears temporaries with its prefix.
    summary = run.summary
    exploration = run.exploration.set_index("planner")
    atomic_write_text(
        METRICS_PATH,
        json.dumps(
            {
                planner: {
                    "distance_mean_m": round(float(row.distance_mean_m), 2),
                    "distance_std_m": round(float(row.distance_std_m), 2),
                    "completion_rate": round(float(row.completion_rate), 4),
                    "decision_ms_median": round(float(row.decision_ms_median), 3),
                    **{name: round(value, 4) for name, value in exploration_metrics(exploration, str(planner)).items()},
                }
                for planner, row in summary.iterrows()
            },
            indent=2,
        )
        + "\n",
    )
    distance_bar_chart(summary, CHART_PATH)
    first, _, _ = run.maps[maps.names[0]]
    planner_paths_figure(first, run.frame, OUT_DIR, FIGURE_PATH)
    log_benchmark(run, OUT_DIR, protocol, experiment="benchmark")
    print((OUT_DIR / "summary.md").read_text())
    team_errors = benchmark_teams(settings, maps)
    raise_planner_errors(run.errors, OUT_DIR)  # the stage fails, after every file is written, with the list
    raise_planner_errors(team_errors, TEAMS_DIR)


def benchmark_teams(settings: Settings, maps: MapSet) -> list[tuple[str, str, str]]:
    """The `team_planners` at each of the `robots` counts on the test mazes (`comm_range_m`:
    None, one shared belief): reports/teams/ (built whole, as reports/benchmark/) and the metrics
    DVC tracks, reports/teams.json. No robots or no team planners: both written empty. Returns
    the episodes whose planner raised (`TeamBenchmarkRun.errors`)."""
    summary: dict = {}
    errors: list[tuple[str, str, str]] = []
    with atomic_folder(TEAMS_DIR) as out_dir:
        if settings.robots and settings.team_planners:
            run = team_benchmark_folder(
                maps,
                settings.team_planners,
                maps.protocol,
                out_dir,
                settings.robots,
                comm_range_m=settings.comm_range_m,
                workers=settings.workers,
                seed=settings.seed,
                speed=SpeedModel(settings.speed_mps),
                experiment="benchmark_teams",
                keep_dir=KEPT_TEAM_EPISODES,
            )
            summary, errors = run.summary, run.errors
    atomic_write_text(TEAMS_METRICS_PATH, json.dumps(summary, indent=2) + "\n")
    return errors
