"""Benchmark many maps x planners in parallel processes and write PROTOCOL.md's outputs."""

from __future__ import annotations

import os
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass
from pathlib import Path
from typing import Sequence

import pandas as pd
from tqdm import tqdm

from pipeline.maps import GroundTruthMap, load_map
from pipeline.planners import make_planner, planner_class
from pipeline.protocol import Protocol
from pipeline.simulator import EpisodeResult, run_episode
from pipeline.trajectories import METRICS_COLUMNS, write_metrics_csv, write_trajectory_csv


REFERENCE_PLANNER = "optimal"


@dataclass(frozen=True)
class EpisodeTask:
    """One (map, planner) episode, picklable for a worker process."""

    map_path: str
    planner: str
    protocol: Protocol
    seed: int


def protocol_for_map(protocol: Protocol, ground_truth: GroundTruthMap) -> Protocol:
    """A ROS map carries its own cell size; every other protocol value stays."""
    if abs(ground_truth.cell_size - protocol.cell_size) > 1e-12:
        return protocol.with_cell_size(ground_truth.cell_size)
    return protocol


def run_task(task: EpisodeTask) -> EpisodeResult:
    ground_truth = load_map(task.map_path, cell_size=task.protocol.cell_size)
    protocol = protocol_for_map(task.protocol, ground_truth)
    return run_episode(ground_truth, make_planner(task.planner), protocol, seed=task.seed)


def default_workers() -> int:
    return max(1, len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (os.cpu_count() or 1))


def run_benchmark(
    map_paths: Sequence[str | Path],
    planners: Sequence[str],
    protocol: Protocol,
    out_dir: str | Path,
    workers: int | None = None,
    seed: int = 0,
    progress: bool = True,
) -> pd.DataFrame:
    """Run every map with every planner; write trajectories, metrics.csv and summary.md.

    Maps are loaded once up front so a malformed map fails before any work starts.
    Failed episodes are kept in the metrics (complete = False), never dropped.
    """
    for name in planners:
        planner_class(name)  # unknown names fail here, with the list of known ones
    for path in map_paths:
        load_map(path, cell_size=protocol.cell_size)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    tasks = [EpisodeTask(str(p), name, protocol, seed) for name in planners for p in map_paths]
    workers = default_workers() if workers is None else max(1, workers)
    results: list[EpisodeResult] = []
    bar = tqdm(total=len(tasks), desc="episodes", unit="ep", disable=not progress)
    if workers == 1 or len(tasks) == 1:
        for task in tasks:
            results.append(_write_result(run_task(task), task, out_dir))
            bar.update()
    else:
        with ProcessPoolExecutor(max_workers=min(workers, len(tasks))) as pool:
            futures = {pool.submit(run_task, task): task for task in tasks}
            for future in as_completed(futures):
                results.append(_write_result(future.result(), futures[future], out_dir))
                bar.update()
    bar.close()
    frame = metrics_frame(results)
    write_metrics_csv(out_dir / "metrics.csv", frame.to_dict("records"))
    (out_dir / "summary.md").write_text(summary_markdown(frame, protocol))
    return frame


def _write_result(result: EpisodeResult, task: EpisodeTask, out_dir: Path) -> EpisodeResult:
    result.map_name = Path(task.map_path).stem
    write_trajectory_csv(out_dir / task.planner / f"{result.map_name}.csv", result.trajectory)
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


def summarise(frame: pd.DataFrame) -> pd.DataFrame:
    """Per planner: mean and std distance, completion rate, decision time."""
    groups = frame.groupby("planner", sort=True)
    summary = pd.DataFrame(
        {
            "episodes": groups.size(),
            "completion_rate": groups["complete"].mean(),
            "distance_mean_m": groups["distance_m"].mean(),
            "distance_std_m": groups["distance_m"].std(ddof=0),
            "decision_ms_median": groups["decision_ms_median"].median(),
            "decision_ms_p95": groups["decision_ms_p95"].median(),
        }
    )
    if REFERENCE_PLANNER in summary.index:
        # The paper's gap: mean distance over the reference's mean distance, minus one.
        summary["gap_to_optimal"] = summary["distance_mean_m"] / summary.loc[REFERENCE_PLANNER, "distance_mean_m"] - 1.0
    return summary.sort_values("distance_mean_m")


def summary_markdown(frame: pd.DataFrame, protocol: Protocol) -> str:
    """A markdown table: mean +- std distance, completion rate, decision time per planner."""
    summary = summarise(frame)
    has_gap = "gap_to_optimal" in summary
    gap_head = " gap to optimal |" if has_gap else ""
    lines = [
        f"| planner | episodes | distance (m) |{gap_head} complete | decision ms (median) | decision ms (p95) |",
        "|---|---:|---:|" + ("---:|" if has_gap else "") + "---:|---:|---:|",
    ]
    for planner, row in summary.iterrows():
        gap = f" {row.gap_to_optimal * 100:+.1f} % |" if has_gap else ""
        lines.append(
            f"| {planner} | {int(row.episodes)} | {row.distance_mean_m:.1f} +- {row.distance_std_m:.1f} |{gap}"
            f" {row.completion_rate * 100:.0f} % | {row.decision_ms_median:.2f} | {row.decision_ms_p95:.2f} |"
        )
    failures = frame[~frame["complete"].astype(bool)]
    notes = [
        "",
        "Distance is measured at completion (ground-truth free minus belief free cells "
        f"<= {protocol.done_unknown_cells}); failed episodes count with the distance they travelled.",
        "Protocol: " + ", ".join(f"{k}={v}" for k, v in protocol.to_dict().items()) + ".",
    ]
    if len(failures):
        notes.append("")
        notes.append(f"Failed episodes ({len(failures)}):")
        for _, row in failures.iterrows():
            notes.append(f"- {row['planner']} on {row['map']}: {row['failure'] or 'incomplete'}")
    else:
        notes.append("Every episode completed.")
    return "\n".join(lines + notes) + "\n"
