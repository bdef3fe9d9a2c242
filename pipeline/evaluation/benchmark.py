"""Benchmark many maps x planners on the executor's engines and write docs/protocol.md's outputs.

Data makes one trip: a benchmark's maps are listed, loaded and hashed once (`MapSet`) and each
planner built once, in the main process, before the episodes (the checks need them); they reach
the episodes as one object, the run's shared inputs (`BenchmarkInputs`: forked worker processes
take it from their copy, a Ray node from its object store), and a planner is reset for each of
its episodes. Each finished episode
is kept under OUT/.episodes/ until the run completes, so a killed run, rerun with the same
command, resumes where it stopped on either engine. The episodes' metrics, per-step records,
exploration table and summary are computed once, in memory, written once and handed back
(`BenchmarkRun`) for the figures and the MLflow runs.
"""

from __future__ import annotations

import json
import shutil
import warnings
from dataclasses import dataclass, field, replace
from functools import cached_property
from pathlib import Path
from typing import Any, Callable, Sequence, TypeVar

import numpy as np
import pandas as pd

from pipeline.common.atomic import atomic_file, atomic_write_text
from pipeline.common.executor import default_workers, resolve_backend, run_tasks
from pipeline.common.fingerprints import files_digest, source_digest
from pipeline.common.kept_results import KeptResults
from pipeline.evaluation.episode_errors import PLANNER_ERROR, ErrorsEndTheEpisode
from pipeline.evaluation.exploration_curves import (
    EXPLORATION_CSV,
    SpeedModel,
    episode_table,
    planner_table,
    records_from_results,
)
from pipeline.evaluation.map_checks import before_episodes, step_limit_hint, unobservable_problem
from pipeline.evaluation.statistics import summarise
from pipeline.models.exports import require_file
from pipeline.planners.config import PlannerConfig
from pipeline.planners.registry import planner_config
from pipeline.planners.specs import PlannerSpec, build_planner, resolve_planner_specs
from pipeline.world.map_files import MapError
from pipeline.world.maps import GroundTruthMap, list_maps, load_map
from pipeline.world.protocol import Protocol, ProtocolMismatchWarning, protocol_for_map
from pipeline.world.simulator import EpisodeResult, run_episode
from pipeline.world.trajectories import (
    METRICS_COLUMNS,
    steps_path,
    write_metrics_csv,
    write_steps_csv,
    write_trajectory_csv,
)

DEFAULT_BASELINE = "greedy_utility"  # summary.md's paired comparison, when it ran
RUN_RECORD = "run.json"  # beside metrics.csv: which planners, options and models ran
COVERAGE_FIGURE = "coverage.png"  # the coverage curves `guide benchmark` draws beside metrics.csv
OUTPUT_FILES = (
    "metrics.csv",
    "summary.md",
    RUN_RECORD,
    EXPLORATION_CSV,
    COVERAGE_FIGURE,
)  # a label names a folder beside these
ERRORS_FILE = "errors.txt"  # beside metrics.csv when a planner raised: each such episode and its traceback
KEPT_EPISODES = ".episodes"  # OUT/.episodes/: the finished episodes of a run not yet complete
T = TypeVar("T")  # a run's task
R = TypeVar("R")  # its episode's result


def with_policy_checkpoint(
    specs: Sequence[PlannerSpec],
    checkpoint: str | Path | None,
    config_of: Callable[[str], type[PlannerConfig]] = planner_config,
) -> list[PlannerSpec]:
    """`specs` with policy_file=PATH added to each diffusion planner's (the command line's --checkpoint);
    ValueError when a checkpoint is given but no planner uses a policy, or a spec names its own too.
    `config_of` finds a name's config (the team registry's `team_config` for team names)."""
    if checkpoint is None:
        return list(specs)
    require_file(checkpoint, "a planner checkpoint")
    out, used = [], False
    for spec in specs:
        if not config_of(spec.name).needs_policy:
            out.append(spec)
            continue
        if {"checkpoint", "policy_file"} & set(spec.options):
            raise ValueError(f"planner {spec.label!r} names its own policy_file; drop it or --checkpoint")
        used = True
        out.append(replace(spec, options={**spec.options, "policy_file": str(checkpoint)}))
    if not used:
        raise ValueError(
            "--checkpoint is a diffusion policy for guide, guide_noregion or dare, and no planner given uses one "
            "(guide_tsp and mapex take an inpainter as label=name:inpainter_file=PATH)"
        )
    return out


@dataclass(frozen=True)
class MapSet:
    """The maps of a benchmark, listed, loaded, checked and hashed once: the episodes read the
    loaded maps, the run record lists the paths, and the resume identity and MLflow's dataset
    input carry the one digest. `folder`: the folder they were listed from (None for a list of
    paths); `start` overrides every map's start (`load_map`)."""

    paths: tuple[str, ...]
    protocol: Protocol
    start: tuple[float, float] | None = None
    folder: str | None = None

    @classmethod
    def of(
        cls, maps: "str | Path | Sequence[str | Path] | MapSet", protocol: Protocol, start: tuple[float, float] | None
    ) -> MapSet:
        """The maps of a folder (MapError when it holds none) or of a list of paths, as a MapSet."""
        if isinstance(maps, MapSet):
            return maps
        if isinstance(maps, (str, Path)):
            paths = list_maps(maps)
            if not paths:
                raise MapError(maps, "no maps in this folder (maze .png, .npy or ROS .yaml)")
            return cls(tuple(map(str, paths)), protocol, start, str(maps))
        return cls(tuple(map(str, maps)), protocol, start)

    @cached_property
    def _read(self) -> tuple[dict[str, tuple[GroundTruthMap, Protocol, bool]], list[str]]:
        loaded: dict[str, tuple[GroundTruthMap, Protocol, bool]] = {}
        problems: list[str] = []
        for path, name in zip(self.paths, self.names):
            if name in loaded:
                raise MapError(
                    path,
                    f"has the same name {name!r} as {self.paths[self.names.index(name)]}: their trajectories "
                    "would overwrite each other in OUT/<label>/<name>.csv; rename one",
                )
            ground_truth = load_map(path, start=self.start, cell_size=self.protocol.cell_size)
            map_protocol = protocol_for_map(self.protocol, ground_truth, path)  # a ROS map brings its cell size
            found, completable = before_episodes(ground_truth, map_protocol, scan_for_unobservable=False)
            loaded[name] = ground_truth, map_protocol, completable
            problems += found
        return loaded, problems

    @property
    def loaded(self) -> dict[str, tuple[GroundTruthMap, Protocol, bool]]:
        """Map name -> (map, the protocol it runs under, whether the checks found it completable);
        MapError when two maps share a name (their trajectory files would overwrite each other)."""
        return self._read[0]

    @property
    def problems(self) -> list[str]:
        """A line for each map no planner can complete (`map_checks`)."""
        return self._read[1]

    @property
    def names(self) -> list[str]:
        return [Path(path).stem for path in self.paths]

    @property
    def cell_sizes(self) -> list[float]:
        return sorted({map_protocol.cell_size for _, map_protocol, _ in self.loaded.values()})

    @cached_property
    def digest(self) -> str:
        """A hash of the maps' files: every file of the folder (a ROS map's image too), else the paths'."""
        return files_digest([self.folder] if self.folder is not None else self.paths)

    def episode_map(self, path: str) -> tuple[GroundTruthMap, Protocol]:
        ground_truth, map_protocol, _ = self.loaded[Path(path).stem]
        return ground_truth, map_protocol


@dataclass(frozen=True)
class EpisodeTask:
    """One (map, planner variant) episode, picklable for a worker process: the spec's label names
    metrics.csv's `planner` and the trajectory folder."""

    map_path: str
    spec: PlannerSpec
    seed: int


@dataclass(frozen=True)
class BenchmarkInputs:
    """What every episode of a run reads (the executor's shared inputs): the maps and the planners
    built for the run's specs (single-robot or team planners), each reset by its episodes."""

    maps: MapSet
    planners: dict[PlannerSpec, Any]


def guarded_episode(
    inputs: BenchmarkInputs, spec: PlannerSpec, episode: Callable[[Any], R]
) -> tuple[R, ErrorsEndTheEpisode]:
    """`episode(planner)` with the run's planner for `spec`, whose exception fails this episode
    only (`ErrorsEndTheEpisode`, returned beside the result to say whether it raised)."""
    with warnings.catch_warnings():
        # The run has said it once, before the episodes; each worker would repeat it.
        warnings.simplefilter("ignore", ProtocolMismatchWarning)
        planner = ErrorsEndTheEpisode(inputs.planners[spec])
        return episode(planner), planner


def run_task(inputs: BenchmarkInputs, task: EpisodeTask) -> EpisodeResult:
    ground_truth, protocol = inputs.maps.episode_map(task.map_path)
    result, planner = guarded_episode(
        inputs, task.spec, lambda planner: run_episode(ground_truth, planner, protocol, seed=task.seed)
    )
    if planner.error:
        result.failure, result.error_traceback, result.complete, result.early_stop = (
            planner.error,
            planner.error_traceback,
            False,
            False,
        )
    result.planner = task.spec.label
    return result


def open_run(
    maps: "str | Path | Sequence[str | Path] | MapSet",
    protocol: Protocol,
    start: tuple[float, float] | None,
    out_dir: str | Path,
    warn: Callable[[str], None] | None,
    other_run: Callable[[Path], bool],
    stale: str,
) -> tuple[MapSet, Path]:
    """The run's maps (each line of `map_checks` said to `warn`) and its output folder, made; the
    warning `stale` (formatted with `out_dir` and `names`) when the folder holds folders of runs
    this one does not write (`other_run`)."""
    map_set = MapSet.of(maps, protocol, start)
    for problem in map_set.problems:
        if warn is not None:
            warn(problem)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if names := sorted(d.name for d in out_dir.iterdir() if d.is_dir() and other_run(d)):
        warnings.warn(stale.format(out_dir=out_dir, names=", ".join(names)), stacklevel=3)
    return map_set, out_dir


def run_kept_episodes(
    run_one: Callable[[BenchmarkInputs, T], R],
    tasks: Sequence[T],
    task_rows: list[list[Any]],
    inputs: BenchmarkInputs,
    descriptions: Sequence[str],
    keep_dir: Path,
    on_result: Callable[[int, R], None],
    *,
    workers: int | None,
    backend: str,
    progress: bool,
    what: str,
    **settings: Any,
) -> None:
    """Every task's episode on the executor's engine, each handed to `on_result` as it finishes and
    kept in `keep_dir` until all are; a rerun with the same identity (the `task_rows`, `settings`,
    protocol, maps, planners' descriptions and code) makes only the rest. The kept ones are dropped
    once the run completes. A Ctrl-C comes through as KeyboardInterrupt."""
    maps = inputs.maps
    identity = {"tasks": task_rows, **settings, "protocol": maps.protocol.to_dict(), "maps": maps.digest}
    keep = KeptResults(keep_dir, {**identity, "planners": list(descriptions), "source": source_digest()})
    workers = default_workers() if workers is None else workers
    run_tasks(
        run_one,  # type: ignore[arg-type]  # with shared, run_tasks calls run_one(shared, task)
        tasks,
        min(workers, len(tasks)),
        what,
        "ep",
        keep=keep,
        backend=backend,
        progress=progress,
        on_result=on_result,
        collect=False,
        shared=inputs,
    )
    shutil.rmtree(keep.folder, ignore_errors=True)


@dataclass
class BenchmarkRun:
    """What a benchmark made, in memory: metrics.csv's rows (`frame`), each episode's per-step
    record ({(label, map): record}), exploration.csv's rows, the per-planner summary, and the maps
    (`maps`: name -> (map, its protocol, whether the checks before the run found it completable))."""

    frame: pd.DataFrame
    records: dict[tuple[str, str], dict[str, np.ndarray]]
    exploration: pd.DataFrame
    summary: pd.DataFrame
    map_set: MapSet
    protocol_record: dict[str, Any] = field(default_factory=dict)  # the protocol as the episodes ran it (run.json's)
    baseline: str | None = None  # summary.md's paired comparison
    errors: list[tuple[str, str, str]] = field(default_factory=list)  # (map, planner, failure) where the planner raised

    @property
    def maps(self) -> dict[str, tuple[GroundTruthMap, Protocol, bool]]:
        return self.map_set.loaded


def run_benchmark(
    maps: str | Path | Sequence[str | Path] | MapSet,
    planners: Sequence[str | PlannerSpec],
    protocol: Protocol,
    out_dir: str | Path,
    workers: int | None = None,
    seed: int = 0,
    progress: bool = True,
    baseline: str | None = DEFAULT_BASELINE,
    start: tuple[float, float] | None = None,
    warn: Callable[[str], None] | None = None,
    speed: SpeedModel = SpeedModel(),
    backend: str | None = None,
    keep_dir: str | Path | None = None,
) -> BenchmarkRun:
    """Run every map with every planner; write trajectories, their per-step files, metrics.csv,
    exploration.csv and summary.md; return them in memory (`BenchmarkRun`).

    `maps`: a folder, a list of map paths or a MapSet (which brings its own protocol and start).
    A planner entry is a registered name or a labelled variant "label=name:key=value,..."
    (see `parse_planner_spec`), or a PlannerSpec; the label is the `planner` column of
    metrics.csv and the trajectory folder OUT/label/.
    Planner specs and maps are checked up front so a typo or a malformed map fails before
    any work starts. Failed episodes are kept in the metrics (complete = False), never dropped.
    summary.md compares every planner with `baseline` map by map when it ran too.
    `start` overrides every map's start (see `load_map`); a .npy grid has no start of its own.
    `warn` receives a line for each map no planner can complete (`map_checks`), before the
    episodes, and after them the likely reason for each map an episode failed on.
    `speed` turns distances and decision times into exploration time (exploration.csv's per-second
    efficiency; `exploration_curves.SpeedModel`).
    `backend` is the executor's engine (`pipeline.common.executor`: process or ray; None:
    $GUIDE_BACKEND, else process). Finished episodes are kept in `keep_dir` (None: OUT/.episodes/)
    until the run completes: the same command run again after a kill makes only the episodes still
    missing. A stage that builds OUT in a temporary folder keeps them outside it, where a rerun finds them.
    """
    backend = resolve_backend(backend)
    specs = resolve_planner_specs(planners, OUTPUT_FILES)
    built = {spec: build_planner(spec) for spec in specs}  # a refused value fails before any map is read
    labels = {spec.label for spec in specs}
    map_set, out_dir = open_run(
        *(maps, protocol, start, out_dir, warn),
        lambda d: d.name not in labels and any(d.glob("*.csv")),
        "{out_dir} holds trajectories of planners this run does not write ({names}); "
        "its metrics.csv and summary.md list only this run's",
    )
    protocol, start = map_set.protocol, map_set.start
    protocol_record = recorded_protocol(protocol, map_set.cell_sizes)
    for planner in built.values():  # models trained at other protocol values: said once here, not by every worker
        planner.check_protocol(protocol)  # (a learned planner takes the protocol's models first: the record names them)
    descriptions = [planner.description for planner in built.values()]
    write_run_record(out_dir / RUN_RECORD, specs, descriptions, seed, start, protocol_record, map_set.paths, speed)
    tasks = [EpisodeTask(path, spec, seed) for spec in specs for path in map_set.paths]
    rows = [[t.map_path, t.spec.name, t.spec.label, t.spec.options_key, t.seed, start] for t in tasks]
    results: list[EpisodeResult] = []
    try:
        run_kept_episodes(
            run_task,
            tasks,
            rows,
            BenchmarkInputs(map_set, built),
            descriptions,
            Path(keep_dir) if keep_dir is not None else out_dir / KEPT_EPISODES,
            lambda index, result: results.append(_write_result(result, tasks[index], out_dir)),
            workers=workers,
            backend=backend,
            progress=progress,
            what="episodes",
        )
    except KeyboardInterrupt:  # Ctrl-C: the finished episodes are kept, as a long run's partial result
        partial = _write_tables(results, out_dir, protocol_record, baseline, speed, map_set) if results else None
        raise BenchmarkInterrupted(len(results), len(tasks), out_dir, partial) from None
    run = _write_tables(results, out_dir, protocol_record, baseline, speed, map_set)
    record_fallbacks(out_dir / RUN_RECORD, run.frame)
    if warn is not None:
        for hint in failure_hints(run.frame, map_set.loaded):
            warn(hint)
    run.errors = write_planner_errors([(r.map_name, r.planner, r.failure, r.error_traceback) for r in results], out_dir)
    return run


class EpisodeErrors(RuntimeError):
    """Episodes whose planner raised. The run went on and wrote every file (these episodes among
    its failures, their trajectories up to the error); `errors` lists (map, planner, failure)."""

    def __init__(self, errors: Sequence[tuple[str, str, str]], out_dir: Path):
        lines = "\n".join(f"  {planner} on {name}: {failure}" for name, planner, failure in errors)
        super().__init__(
            f"{len(errors)} episode{'s' if len(errors) != 1 else ''} failed with a planner error "
            f"(tracebacks in {Path(out_dir) / ERRORS_FILE}):\n{lines}"
        )
        self.errors, self.out_dir = list(errors), Path(out_dir)


def write_planner_errors(episodes: Sequence[tuple[str, str, str, str]], out_dir: Path) -> list[tuple[str, str, str]]:
    """The (map, planner, failure) of the (map, planner, failure, traceback) episodes whose planner
    raised, their tracebacks written to OUT/errors.txt (removed when none did)."""
    errors = [
        (name, planner, failure, trace)
        for name, planner, failure, trace in episodes
        if failure.startswith(PLANNER_ERROR)
    ]
    (Path(out_dir) / ERRORS_FILE).unlink(missing_ok=True)
    if errors:
        atomic_write_text(
            Path(out_dir) / ERRORS_FILE,
            "".join(f"{planner} on {name}: {failure}\n{trace}\n" for name, planner, failure, trace in errors),
        )
    return [(name, planner, failure) for name, planner, failure, _ in errors]


def raise_planner_errors(errors: Sequence[tuple[str, str, str]], out_dir: Path) -> None:
    """EpisodeErrors when a run's planners raised (`BenchmarkRun.errors`): the last thing a command
    or stage does, after every file is written, so that it exits non-zero with the list."""
    if errors:
        raise EpisodeErrors(errors, out_dir)


def failure_hints(frame: pd.DataFrame, loaded: dict[str, tuple[GroundTruthMap, Protocol, bool]]) -> list[str]:
    """Why episodes failed, per map: a step limit too small for its size, or cells no scan reveals
    (worth a scan per failed map, but not one per map before the run). `loaded`: map name ->
    (map, its protocol, whether the checks before the run found it completable)."""
    failed = frame[~frame["complete"].astype(bool)]
    hints = []
    for name in sorted(set(failed["map"])):
        ground_truth, protocol, _ = loaded[name]
        if (failed.loc[failed["map"] == name, "steps"] >= protocol.max_steps).any():
            hints.append(step_limit_hint(ground_truth, protocol))
    for name in sorted(set(failed["map"])):
        ground_truth, protocol, completable = loaded[name]
        problem = unobservable_problem(ground_truth, protocol) if completable else None
        if problem:
            hints.append(problem)
    return hints


class BenchmarkInterrupted(KeyboardInterrupt):
    """Ctrl-C during a benchmark, after `done` of `total` episodes (their metrics.csv is written and
    `run` holds their tables; they stay kept in OUT/.episodes/, so the same command resumes the run)."""

    def __init__(self, done: int, total: int, out_dir: Path, run: "BenchmarkRun | None" = None):
        super().__init__(f"interrupted after {done} of {total} episodes")
        self.done, self.total, self.out_dir, self.run = done, total, out_dir, run


def _write_tables(
    results: Sequence[EpisodeResult],
    out_dir: Path,
    protocol_record: dict[str, Any],
    baseline: str | None,
    speed: SpeedModel,
    maps: MapSet,
) -> BenchmarkRun:
    """metrics.csv and exploration.csv from the episodes, and the run they make (summary.md is
    reporting's: `pipeline.reporting.benchmark_markdown.write_summary`)."""
    frame = metrics_frame(results)
    write_metrics_csv(out_dir / "metrics.csv", frame.to_dict("records"))
    records = records_from_results(results)
    exploration = planner_table(episode_table(records, speed), speed)
    with atomic_file(out_dir / EXPLORATION_CSV) as tmp:
        exploration.to_csv(tmp, index=False, float_format="%.6g")
    return BenchmarkRun(frame, records, exploration, summarise(frame), maps, protocol_record, baseline)


def recorded_protocol(protocol: Protocol, cell_sizes: Sequence[float]) -> dict[str, Any]:
    """The protocol as the episodes ran it: ROS maps bring their own cell size (a list when they differ)."""
    record = protocol.to_dict()
    if list(cell_sizes) not in ([], [protocol.cell_size]):
        record["cell_size"] = cell_sizes[0] if len(cell_sizes) == 1 else list(cell_sizes)
    return record


def write_run_record(
    path: Path,
    specs: Sequence[PlannerSpec],
    descriptions: Sequence[str],
    seed: int,
    start: tuple[float, float] | None,
    protocol: dict[str, Any],
    maps: Sequence[str],
    speed: SpeedModel = SpeedModel(),
    extra: dict[str, Any] | None = None,
) -> dict[str, Any]:
    """What ran: per label the planner, its options and its description (which names the policy
    and predictor files a learned planner loaded), with the seed, any start override, the
    protocol (`recorded_protocol`), the maps, the speed model's speed and any `extra` settings
    (a team benchmark's robot counts and range)."""
    record = {
        **(extra or {}),
        "seed": seed,
        "start": list(start) if start is not None else None,
        "protocol": protocol,
        "maps": list(maps),
        "speed_mps": speed.speed_mps,
        "planners": {
            spec.label: {"name": spec.name, "options": dict(spec.options), "description": description}
            for spec, description in zip(specs, descriptions)
        },
    }
    atomic_write_text(path, json.dumps(record, indent=2) + "\n")
    return record


def record_fallbacks(path: Path, frame: pd.DataFrame) -> None:
    """Add to run.json, per label, the fallback decisions of each map's episode (the whole
    building's nearest-frontier fallback and the way back to the lattice), where there were any."""
    counts = {
        str(label): {str(m): int(n) for m, n in zip(rows["map"], rows["fallbacks"]) if n}
        for label, rows in frame.groupby("planner", sort=True)
    }
    record = json.loads(path.read_text())
    record["fallbacks"] = {label: maps for label, maps in counts.items() if maps}
    atomic_write_text(path, json.dumps(record, indent=2) + "\n")


def _write_result(result: EpisodeResult, task: EpisodeTask, out_dir: Path) -> EpisodeResult:
    result.map_name = Path(task.map_path).stem
    result.planner = task.spec.label
    trajectory = write_trajectory_csv(out_dir / task.spec.label / f"{result.map_name}.csv", result.trajectory)
    write_steps_csv(steps_path(trajectory), result.step_rows())
    return result


def metrics_frame(results: Sequence[EpisodeResult]) -> pd.DataFrame:
    """metrics.csv rows, sorted by planner then map, plus a `failure` column for reports."""
    rows = []
    for result in results:
        row = result.metrics_row()
        row["failure"] = result.failure
        rows.append(row)
    frame = pd.DataFrame(rows, columns=METRICS_COLUMNS + ["failure"])
    return frame.sort_values(["planner", "map"]).reset_index(drop=True)
