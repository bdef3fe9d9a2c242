"""Team benchmarks: every planner spec with every robot count on every map (`pipeline.world.team`).

A team run is one planner spec at one robot count, named `<label>@<robots>` (`greedy_utility@3`,
`g5=greedy_utility:min_utility=5` at 3 robots is `g5@3`): the name of its folder, its rows in the
tables and its MLflow run. The count is in the name at every count, 1 included, so team folders
never mix with a single-robot benchmark's `OUT/<label>/` (a label cannot hold `@`). A planner name
means its coordinated team version where one is registered, else every robot runs that planner
uncoordinated (`pipeline.planners.team.registry`).

The episodes run on the single-robot benchmark's engine (`pipeline.evaluation.benchmark`: maps
and planners read and built once, finished episodes kept, here in OUT/.team_episodes/, until the
run completes); the tables are written in task order, so a resumed run writes the same files.

Files: OUT/<run>/<map>.team.csv (the team trajectory, times at the speed model's speed), its
merges file beside it under a communication range, OUT/<run>/<map>.robots.csv (per robot:
distance, moves, median decision time), OUT/team_metrics.csv, OUT/team_coverage.csv,
OUT/team_summary.json and OUT/team_run.json (what ran).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np
import pandas as pd

from pipeline.common.atomic import atomic_file, atomic_write_text
from pipeline.common.executor import resolve_backend
from pipeline.evaluation.benchmark import (
    BenchmarkInputs,
    BenchmarkInterrupted,
    MapSet,
    guarded_episode,
    open_run,
    recorded_protocol,
    run_kept_episodes,
    write_planner_errors,
    write_run_record,
)
from pipeline.evaluation.exploration_curves import SpeedModel
from pipeline.planners.specs import PlannerSpec, check_reserved, parse_planner_spec
from pipeline.planners.team.registry import make_team_planner
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.team import MAX_ROBOTS, TeamEpisodeResult, TeamPlanner, run_team_episode
from pipeline.world.team_files import TEAM_SUFFIX, merges_path, write_merges_csv, write_team_csv

TEAM_METRICS_CSV = "team_metrics.csv"
TEAM_COVERAGE_CSV = "team_coverage.csv"
TEAM_SUMMARY_JSON = "team_summary.json"
TEAM_RUN_RECORD = "team_run.json"
TEAM_COVERAGE_FIGURE = "team_coverage.png"
ROBOTS_SUFFIX = ".robots.csv"
TEAM_KEPT_EPISODES = ".team_episodes"
TEAM_OUTPUT_FILES = (TEAM_METRICS_CSV, TEAM_COVERAGE_CSV, TEAM_SUMMARY_JSON, TEAM_RUN_RECORD, TEAM_COVERAGE_FIGURE)
ROBOT_COLUMNS = ["robot", "distance_m", "moves", "decision_ms_median"]
COVERAGE_COLUMNS = ["label", "map", "robots", "time_m", "explored_share"]
METRICS_COLUMNS = [
    "label",
    "map",
    "planner",
    "robots",
    "comm_range_m",
    "makespan_m",
    "total_distance_m",
    "max_robot_distance_m",
    "time_to_90_m",
    "complete",
    "explored_ratio",
    "decision_ms_median",
    "merges",
    "seed",
]


def team_run_label(label: str, robots: int) -> str:
    """The name of a planner spec's team run at `robots` robots: its folder and MLflow run."""
    return f"{label}@{robots}"


def check_robot_counts(robots: Sequence[int]) -> list[int]:
    """The robot counts, each once, in increasing order; ValueError for none or one outside 1-MAX_ROBOTS."""
    counts = list(robots)
    if not counts:
        raise ValueError("give at least one robot count")
    for count in counts:
        if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or not 1 <= count <= MAX_ROBOTS:
            raise ValueError(f"robot counts must be whole numbers 1-{MAX_ROBOTS}, got {count!r}")
    return sorted({int(count) for count in counts})


def check_comm_range(comm_range_m: float | None) -> float | None:
    """The communication range in metres (None: full communication); ValueError unless positive and finite."""
    if comm_range_m is None:
        return None
    if (
        isinstance(comm_range_m, bool)
        or not isinstance(comm_range_m, (int, float))
        or not (math.isfinite(comm_range_m) and comm_range_m > 0)
    ):
        raise ValueError(f"the communication range must be a positive number of metres, got {comm_range_m!r}")
    return float(comm_range_m)


def resolve_team_specs(planners: Sequence[str | PlannerSpec]) -> list[tuple[PlannerSpec, TeamPlanner]]:
    """Each entry parsed (`parse_planner_spec`) and built as a team planner (`make_team_planner`);
    ValueError naming the label for an unknown name, a refused option or a label used twice."""
    resolved: list[tuple[PlannerSpec, TeamPlanner]] = []
    seen: set[str] = set()
    for entry in planners:
        spec = (
            check_reserved(entry, TEAM_OUTPUT_FILES)
            if isinstance(entry, PlannerSpec)
            else parse_planner_spec(entry, TEAM_OUTPUT_FILES)
        )
        if spec.label in seen:
            raise ValueError(f"planner label {spec.label!r} is used twice; give each variant its own label")
        seen.add(spec.label)
        try:
            planner = make_team_planner(spec.name, **spec.options)
        except (TypeError, ValueError) as error:  # UnknownPlannerError is a ValueError too
            message = str(error)
            raise ValueError(
                message if message.startswith("unknown") else f"planner {spec.label!r}: {message}"
            ) from None
        resolved.append((spec, planner))
    return resolved


@dataclass(frozen=True)
class TeamEpisodeTask:
    """One (map, planner spec, robot count) team episode, picklable for a worker."""

    map_path: str
    spec: PlannerSpec  # its name is the one `make_team_planner` takes; the run is `label@robots`
    robots: int
    seed: int
    comm_range_m: float | None = None

    @property
    def label(self) -> str:
        return self.spec.label

    @property
    def run_label(self) -> str:
        return team_run_label(self.spec.label, self.robots)


def run_team_task(inputs: BenchmarkInputs, task: TeamEpisodeTask) -> TeamEpisodeResult:
    """One team episode with the run's map and planner (the executor's shared inputs)."""
    ground_truth, protocol = inputs.maps.episode_map(task.map_path)
    result, planner = guarded_episode(
        inputs,
        task.spec,
        lambda planner: run_team_episode(
            ground_truth, planner, protocol, task.robots, comm_range_m=task.comm_range_m, seed=task.seed
        ),
    )
    if planner.error:
        result.failure, result.complete = planner.error, False
    result.map_name = Path(task.map_path).stem
    return result


@dataclass
class TeamBenchmarkRun:
    """What a team benchmark made, in memory: team_metrics.csv's rows (`frame`), team_coverage.csv's
    rows (`coverage`), team_summary.json (`summary`, by run label), the episodes with their tasks in
    task order, what ran (team_run.json's `record`) and the maps (name -> (map, its protocol,
    whether the checks before the run found it completable))."""

    frame: pd.DataFrame
    coverage: pd.DataFrame
    summary: dict[str, dict[str, Any]]
    episodes: list[tuple[TeamEpisodeTask, TeamEpisodeResult]]
    record: dict[str, Any]
    map_set: MapSet
    errors: list[tuple[str, str, str]] = field(
        default_factory=list
    )  # (map, run label, failure) where the planner raised

    @property
    def maps(self) -> dict[str, tuple[GroundTruthMap, Protocol, bool]]:
        return self.map_set.loaded


def run_team_benchmark(
    maps: str | Path | Sequence[str | Path] | MapSet,
    planners: Sequence[str | PlannerSpec],
    protocol: Protocol,
    out_dir: str | Path,
    robots: Sequence[int],
    comm_range_m: float | None = None,
    workers: int | None = None,
    seed: int = 0,
    progress: bool = True,
    start: tuple[float, float] | None = None,
    warn: Callable[[str], None] | None = None,
    speed: SpeedModel = SpeedModel(),
    backend: str | None = None,
    keep_dir: str | Path | None = None,
) -> TeamBenchmarkRun:
    """Run every planner spec at every robot count on every map; write the files the module's doc
    lists and return them in memory (`TeamBenchmarkRun`).

    Every robot starts at the map's start (`start` overrides every map's, as in `load_map`).
    `comm_range_m` None is full communication (one team belief), else the range within which
    robots merge their beliefs. Failed episodes are kept in the tables (complete False).
    `warn` receives a line for each map no planner can complete, before the episodes. `speed`
    converts the team files' times to seconds. `workers`, `backend` and the kept episodes are
    the single-robot benchmark's (`run_benchmark`), `keep_dir` too.
    """
    backend = resolve_backend(backend)
    counts = check_robot_counts(robots)
    comm_range_m = check_comm_range(comm_range_m)
    resolved = resolve_team_specs(planners)  # a refused name or value fails before any map is read
    run_labels = {team_run_label(spec.label, count) for spec, _ in resolved for count in counts}
    map_set, out_dir = open_run(
        *(maps, protocol, start, out_dir, warn),
        lambda d: "@" in d.name and d.name not in run_labels and any(d.glob("*" + TEAM_SUFFIX)),
        "{out_dir} holds team trajectories of runs this one does not write ({names}); "
        f"its {TEAM_METRICS_CSV} lists only this run's",
    )
    protocol, start = map_set.protocol, map_set.start
    for _, planner in resolved:  # models trained at other protocol values: said once here, not by every worker
        planner.check_protocol(protocol)
    specs = [spec for spec, _ in resolved]
    descriptions = [planner.description for _, planner in resolved]
    record = write_run_record(
        out_dir / TEAM_RUN_RECORD,
        specs,
        descriptions,
        seed,
        start,
        recorded_protocol(protocol, map_set.cell_sizes),
        map_set.paths,
        speed,
        extra={"robots": counts, "comm_range_m": comm_range_m},
    )
    tasks = [
        TeamEpisodeTask(path, spec, count, seed, comm_range_m)
        for spec in specs
        for count in counts
        for path in map_set.paths
    ]
    rows = [
        [t.map_path, t.spec.name, t.spec.label, t.robots, t.spec.options_key, t.seed, t.comm_range_m] for t in tasks
    ]
    finished: dict[int, TeamEpisodeResult] = {}

    def on_result(index: int, result: TeamEpisodeResult) -> None:
        write_episode_files(result, tasks[index], out_dir, speed)
        finished[index] = result

    try:
        run_kept_episodes(
            run_team_task,
            tasks,
            rows,
            BenchmarkInputs(map_set, dict(resolved)),
            descriptions,
            Path(keep_dir) if keep_dir is not None else out_dir / TEAM_KEPT_EPISODES,
            on_result,
            workers=workers,
            backend=backend,
            progress=progress,
            what="team episodes",
            start=list(start) if start is not None else None,
        )
    except KeyboardInterrupt:  # Ctrl-C: the finished episodes are kept, as a long run's partial result
        if finished:
            write_team_tables([(tasks[i], finished[i]) for i in sorted(finished)], out_dir, record, map_set)
        raise BenchmarkInterrupted(len(finished), len(tasks), out_dir) from None
    episodes = [(tasks[i], finished[i]) for i in sorted(finished)]
    run = write_team_tables(episodes, out_dir, record, map_set)
    run.errors = write_planner_errors(
        [(result.map_name, task.run_label, result.failure, "") for task, result in episodes], out_dir
    )
    return run


def write_episode_files(result: TeamEpisodeResult, task: TeamEpisodeTask, out_dir: Path, speed: SpeedModel) -> Path:
    """OUT/<run>/<map>.team.csv, its merges file under a range, and <map>.robots.csv; the team file's path."""
    return write_team_files(result, out_dir / task.run_label, task.comm_range_m is not None, speed)[0]


def write_team_files(result: TeamEpisodeResult, folder: Path, merges: bool, speed: SpeedModel) -> list[Path]:
    """FOLDER/<map>.team.csv, its merges file when `merges` (under a range), and <map>.robots.csv;
    the paths written, the team file first."""
    team_file = write_team_csv(folder / f"{result.map_name}{TEAM_SUFFIX}", result.rows, speed.speed_mps)
    written = [team_file]
    if merges:
        written.append(write_merges_csv(merges_path(team_file), result.merges, speed.speed_mps))
    robots_file = folder / f"{result.map_name}{ROBOTS_SUFFIX}"
    with atomic_file(robots_file) as tmp:
        robot_table(result).to_csv(tmp, index=False, float_format="%.6g")
    return [*written, robots_file]


def robot_table(result: TeamEpisodeResult) -> pd.DataFrame:
    """Per robot of an episode: its distance, its moves (rows after its start) and its median decision time."""
    moves = np.bincount([robot for _, robot, _, _ in result.rows], minlength=result.robots) - 1
    return pd.DataFrame(
        {
            "robot": np.arange(result.robots),
            "distance_m": np.round(result.robot_distance_m, 3),
            "moves": moves,
            "decision_ms_median": [
                round(float(np.median(ms)), 3) if len(ms) else float("nan") for ms in result.decision_ms
            ],
        },
        columns=ROBOT_COLUMNS,
    )


def coverage_rows(task: TeamEpisodeTask, result: TeamEpisodeResult) -> list[dict[str, Any]]:
    """team_coverage.csv's rows of an episode: the union belief's explored share after each event
    (an event that changed neither time nor share is left out)."""
    rows, last = [], None
    for time_m, share in result.coverage:
        point = (round(time_m, 6), round(share, 6))
        if point != last:
            rows.append(
                {
                    "label": task.run_label,
                    "map": result.map_name,
                    "robots": task.robots,
                    "time_m": point[0],
                    "explored_share": point[1],
                }
            )
            last = point
    return rows


def write_team_tables(
    episodes: Sequence[tuple[TeamEpisodeTask, TeamEpisodeResult]], out_dir: Path, record: dict[str, Any], maps: MapSet
) -> TeamBenchmarkRun:
    """team_metrics.csv, team_coverage.csv and team_summary.json from the episodes (in task order)."""
    frame = pd.DataFrame(
        [{**result.metrics_row(), "label": task.run_label} for task, result in episodes], columns=METRICS_COLUMNS
    )
    with atomic_file(out_dir / TEAM_METRICS_CSV) as tmp:
        frame.to_csv(tmp, index=False)
    coverage = pd.DataFrame(
        [row for task, result in episodes for row in coverage_rows(task, result)], columns=COVERAGE_COLUMNS
    )
    with atomic_file(out_dir / TEAM_COVERAGE_CSV) as tmp:
        coverage.to_csv(tmp, index=False)
    summary = team_summary(episodes, record)
    atomic_write_text(out_dir / TEAM_SUMMARY_JSON, json.dumps(summary, indent=2) + "\n")
    return TeamBenchmarkRun(frame, coverage, summary, list(episodes), record, maps)


def _finite(value: float | np.floating, decimals: int = 3) -> float | None:
    """A number for JSON: rounded, or None for nan (no episode reached it)."""
    return round(float(value), decimals) if np.isfinite(value) else None


def team_summary(
    episodes: Sequence[tuple[TeamEpisodeTask, TeamEpisodeResult]], record: dict[str, Any]
) -> dict[str, dict[str, Any]]:
    """Per run (`label@robots`, in task order): makespan mean and std, total distance, time to 90 %
    of the free area (over the episodes that reached it), completion rate, median decision time
    and, when the same spec also ran with one robot, the mean over maps of the makespan over
    that robot's distance (1 for the one-robot run; below 1: the team finishes sooner).
    Distances and times in metres of travel."""
    by_run: dict[str, list[tuple[TeamEpisodeTask, TeamEpisodeResult]]] = {}
    for task, result in episodes:
        by_run.setdefault(task.run_label, []).append((task, result))
    single = {(task.label, result.map_name): result.total_distance_m for task, result in episodes if task.robots == 1}
    summary: dict[str, dict[str, Any]] = {}
    for run_label, group in by_run.items():
        task = group[0][0]
        results = [result for _, result in group]
        makespans = np.array([r.makespan_m for r in results])
        to_90 = np.array([r.time_to_share(0.9) for r in results])
        medians = [float(np.median(ms)) for r in results if (ms := [m for robot in r.decision_ms for m in robot])]
        ratios = [
            r.makespan_m / single[task.label, r.map_name]
            for r in results
            if single.get((task.label, r.map_name), 0) > 0
        ]
        summary[run_label] = {
            "label": task.label,
            "planner": results[0].planner,
            "description": record.get("planners", {}).get(task.label, {}).get("description", ""),
            "robots": task.robots,
            "comm_range_m": task.comm_range_m,
            "episodes": len(results),
            "makespan_mean_m": _finite(makespans.mean()),
            "makespan_std_m": _finite(makespans.std(ddof=0)),
            "total_distance_mean_m": _finite(np.mean([r.total_distance_m for r in results])),
            "time_to_90_mean_m": _finite(to_90[np.isfinite(to_90)].mean()) if np.isfinite(to_90).any() else None,
            "completion_rate": round(float(np.mean([r.complete for r in results])), 4),
            "decision_ms_median": _finite(np.median(medians)) if medians else None,
            "makespan_over_single_distance": _finite(np.mean(ratios), 4) if ratios else None,
        }
    return summary
