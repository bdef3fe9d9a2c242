"""MLflow runs of a benchmark: one run per planner (one per planner and robot count for a team
benchmark), with its options, summary metrics and tables."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Sequence

import pandas as pd

from pipeline.common.mlflow_store import import_mlflow, maze_set_input, resolve_tracking_uri
from pipeline.evaluation.benchmark import COVERAGE_FIGURE, RUN_RECORD, BenchmarkRun, MapSet
from pipeline.evaluation.exploration_curves import EXPLORATION_CSV
from pipeline.evaluation.team_benchmark import (
    TEAM_COVERAGE_FIGURE,
    TEAM_METRICS_CSV,
    TEAM_SUMMARY_JSON,
    TeamBenchmarkRun,
)
from pipeline.world.protocol import Protocol


def maze_set_logger(map_set: MapSet):
    """A function that records the run's maze set as a dataset input of the active MLflow run, its
    dataset made once (from the folder the maps were listed from; a list of paths is not logged)."""
    mlflow = import_mlflow()
    if map_set.folder is None:
        return lambda: None
    dataset, tags = maze_set_input(map_set.folder, "evaluation", map_set.digest)
    return lambda: mlflow.log_input(dataset, context="evaluation", tags=tags)


@dataclass(frozen=True)
class TrackedRun:
    """One MLflow run of a benchmark: its name, params and metrics."""

    name: str
    params: dict[str, Any]
    metrics: dict[str, float]


def log_runs(
    runs: Sequence[TrackedRun],
    out_dir: Path,
    artifacts: Sequence[str],
    map_set: MapSet,
    tracking_uri: str | None,
    experiment: str,
) -> list[str]:
    """One MLflow run per entry of `runs` in `experiment`, each with the maze set as its dataset
    input, its params and metrics, and as artifacts the files of `artifacts` that `out_dir` holds.
    Returns the run ids."""
    mlflow = import_mlflow()
    mlflow.set_tracking_uri(resolve_tracking_uri(tracking_uri))
    mlflow.set_experiment(experiment)
    log_maze_set = maze_set_logger(map_set)
    run_ids = []
    for tracked in runs:
        with mlflow.start_run(run_name=tracked.name) as active:
            log_maze_set()
            mlflow.log_params(tracked.params)
            mlflow.log_metrics(tracked.metrics)
            for name in artifacts:
                if (out_dir / name).is_file():
                    mlflow.log_artifact(str(out_dir / name))
            run_ids.append(active.info.run_id)
    return run_ids


def planner_params(record: dict[str, Any], label: str) -> dict[str, Any]:
    """The planner's name, options and description and the run's seed, from its run record
    (run.json or team_run.json); none when the record does not list the planner."""
    ran = record.get("planners", {}).get(label, {})
    if not ran:
        return {}
    return {
        "planner_name": ran.get("name", label),
        "planner_options": json.dumps(ran.get("options", {}), sort_keys=True),
        "planner_description": str(ran.get("description", ""))[:500],
        "seed": record.get("seed"),
    }


def log_benchmark(
    run: BenchmarkRun,
    out_dir: str | Path,
    protocol: Protocol,
    tracking_uri: str | None = None,
    experiment: str = "benchmark",
) -> list[str]:
    """One MLflow run per planner of a benchmark `run` written to `out_dir`: protocol params, the
    planner's name, options and description (from its run.json), summary metrics, the exploration metrics (exploration.csv:
    distance to 50 / 90 / 99 %, coverage AUC, Table V efficiency), and as artifacts summary.md,
    metrics.csv, exploration.csv and the coverage figure; the run's maze set is each run's dataset
    input, with its DVC hash when a stage made it.

    Returns the run ids.
    """
    out_dir = Path(out_dir)
    record_path = out_dir / RUN_RECORD
    record = json.loads(record_path.read_text()) if record_path.is_file() else {}
    exploration = run.exploration.set_index("planner")
    tracked = [
        TrackedRun(
            str(planner),
            {
                **record.get("protocol", protocol.to_dict()),
                "planner": planner,
                "maps": run.map_set.folder,
                "episodes": int(row.episodes),
                **planner_params(record, str(planner)),
            },
            {
                "distance_mean_m": float(row.distance_mean_m),
                "distance_std_m": float(row.distance_std_m),
                "completion_rate": float(row.completion_rate),
                "decision_ms_median": float(row.decision_ms_median),
                "decision_ms_p95": float(row.decision_ms_p95),
                **exploration_metrics(exploration, str(planner)),
            },
        )
        for planner, row in run.summary.iterrows()
    ]
    artifacts = ("summary.md", "metrics.csv", EXPLORATION_CSV, COVERAGE_FIGURE)
    return log_runs(tracked, out_dir, artifacts, run.map_set, tracking_uri, experiment)


EXPLORATION_METRICS = (
    "distance_to_50_m",
    "distance_to_90_m",
    "distance_to_99_m",
    "coverage_auc",
    "efficiency_m2_per_m",
    "efficiency_m2_per_s",
    "time_s",
)


def exploration_metrics(exploration: pd.DataFrame, planner: str) -> dict[str, float]:
    """A planner's finite exploration.csv figures as MLflow metrics (a level no map reached is left out)."""
    if planner not in exploration.index:
        return {}
    row = exploration.loc[planner]
    return {name: float(row[name]) for name in EXPLORATION_METRICS if name in row and pd.notna(row[name])}


TEAM_METRICS = (
    "makespan_mean_m",
    "makespan_std_m",
    "total_distance_mean_m",
    "time_to_90_mean_m",
    "completion_rate",
    "decision_ms_median",
    "makespan_over_single_distance",
)


def log_team_benchmark(
    run: TeamBenchmarkRun,
    out_dir: str | Path,
    protocol: Protocol,
    tracking_uri: str | None = None,
    experiment: str = "benchmark",
) -> list[str]:
    """One MLflow run per team run (`label@robots`) of a team benchmark written to `out_dir`, as
    `log_benchmark` logs one per planner: protocol params, the planner's name, options and
    description, the robot count and range, team_summary.json's figures as metrics (those no
    episode reached left out), and as artifacts team_summary.json, team_metrics.csv and the
    team coverage figure; the run's maze set is each run's dataset input.

    Returns the run ids.
    """
    record = run.record
    tracked = [
        TrackedRun(
            run_label,
            {
                **record.get("protocol", protocol.to_dict()),
                "planner": row["label"],
                "maps": run.map_set.folder,
                "episodes": int(row["episodes"]),
                "robots": int(row["robots"]),
                "comm_range_m": "none" if row["comm_range_m"] is None else row["comm_range_m"],
                "planner_name": row["label"],
                "planner_options": "{}",
                "planner_description": "",
                "seed": record.get("seed"),
                **planner_params(record, row["label"]),
            },
            {name: float(row[name]) for name in TEAM_METRICS if row.get(name) is not None},
        )
        for run_label, row in run.summary.items()
    ]
    artifacts = (TEAM_SUMMARY_JSON, TEAM_METRICS_CSV, TEAM_COVERAGE_FIGURE)
    return log_runs(tracked, Path(out_dir), artifacts, run.map_set, tracking_uri, experiment)
