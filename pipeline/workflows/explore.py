"""Explore one map with one planner and write what `guide explore` shows: trajectory CSV,
its per-step record, metrics, the final picture (and an animation), and run.json saying what ran."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

from tqdm import tqdm

from pipeline.common.atomic import atomic_write_text
from pipeline.evaluation.benchmark import with_policy_checkpoint
from pipeline.evaluation.map_checks import before_episodes, step_limit_hint
from pipeline.planners.specs import as_specs, build_planner, resolve_planner_specs
from pipeline.planners.wrapper import innermost
from pipeline.reporting.panels import render_final
from pipeline.reporting.recorder import EpisodeRecorder
from pipeline.robot.recording import EpisodeRecording
from pipeline.world.maps import GroundTruthMap, load_map
from pipeline.world.planner import Planner
from pipeline.world.protocol import Protocol, protocol_for_map
from pipeline.world.simulator import EpisodeResult, final_belief, run_episode
from pipeline.world.trajectories import steps_path, write_metrics_csv, write_steps_csv, write_trajectory_csv

DEFAULT_OUT = Path("runs/explore")


@dataclass
class Exploration:
    """One planner on one map, before the episode runs: everything checked and built."""

    map_path: Path
    ground_truth: GroundTruthMap
    protocol: Protocol  # the map's own cell size for a ROS map
    label: str
    name: str
    options: dict
    planner: Planner
    out: Path
    problems: list[str] = field(default_factory=list)  # why the map may not complete, said before the episode


def prepare(
    map_path: Path,
    planner: str,
    protocol: Protocol,
    out: Path | None = None,
    start: tuple[float, float] | None = None,
    checkpoint: Path | None = None,
) -> Exploration:
    """Load the map, build the planner and check both, before any work (ValueError, MapError,
    FileNotFoundError in one line)."""
    ground_truth = load_map(map_path, start=start, cell_size=protocol.cell_size)
    protocol = protocol_for_map(protocol, ground_truth, map_path)
    (spec,) = resolve_planner_specs(with_policy_checkpoint(as_specs([planner]), checkpoint))
    agent = build_planner(spec)
    problems, _ = before_episodes(ground_truth, protocol, scan_for_unobservable=True)
    return Exploration(
        Path(map_path),
        ground_truth,
        protocol,
        spec.label,
        spec.name,
        dict(spec.options),
        agent,
        out if out is not None else DEFAULT_OUT / spec.label,
        problems,
    )


def is_ros_map(path: Path) -> bool:
    return path.suffix.lower() in (".yaml", ".yml")


def run(
    exploration: Exploration,
    seed: int = 0,
    gif: bool = False,
    progress: bool = True,
    start: tuple[float, float] | None = None,
    bag: Path | None = None,
) -> tuple[EpisodeResult, list[Path]]:
    """Run the episode with a progress bar and write its files; (the result, the files written).
    With `bag`, also an MCAP recording of the episode (belief, pose, plans, graph) for Foxglove."""
    ground_truth, protocol, agent, out = (
        exploration.ground_truth,
        exploration.protocol,
        exploration.planner,
        exploration.out,
    )
    recording = EpisodeRecording(bag, agent) if bag is not None else None
    y_up = is_ros_map(exploration.map_path)
    recorder = (
        EpisodeRecorder(
            graph_provider=lambda: getattr(innermost(agent), "graph", None), label=exploration.label, y_up=y_up
        )
        if gif
        else None
    )
    with tqdm(
        total=100.0,
        desc=f"{ground_truth.name}: explored",
        disable=not progress,
        leave=False,
        bar_format="{desc} {percentage:3.0f}%|{bar}|",
    ) as bar:

        def on_step(episode) -> None:
            bar.n = round(100.0 * episode.explored_ratio, 1)
            bar.set_description_str(
                f"{ground_truth.name}: {episode.distance:.0f} m, {episode.steps} waypoints, explored", refresh=True
            )
            if recorder is not None:
                recorder(episode)
            if recording is not None:
                recording.on_step(episode)

        try:
            result = run_episode(
                ground_truth,
                recording.planner if recording is not None else agent,
                protocol,
                seed=seed,
                on_step=on_step,
            )
        finally:
            if recording is not None:
                recording.close()
    result.planner = exploration.label
    written = [write_trajectory_csv(out / f"{ground_truth.name}.csv", result.trajectory)]
    written.append(write_steps_csv(steps_path(written[0]), result.step_rows()))
    write_metrics_csv(out / "metrics.csv", [result.metrics_row()])
    written.append(out / "metrics.csv")
    render_final(
        result,
        ground_truth,
        final_belief(ground_truth, result.trajectory, protocol),
        graph=getattr(innermost(agent), "graph", None),
        path=out / f"{ground_truth.name}.png",
        y_up=y_up,
    )
    written.append(out / f"{ground_truth.name}.png")
    if recorder is not None:
        written.append(recorder.save_gif(out / f"{ground_truth.name}.gif"))
    if recording is not None:
        written.append(recording.recording.path)
    record = {
        "map": str(exploration.map_path),
        "start": list(start) if start is not None else None,
        "seed": seed,
        "planner": {
            "label": exploration.label,
            "name": exploration.name,
            "options": exploration.options,
            "description": agent.description,
        },
        "protocol": protocol.to_dict(),
    }
    trust = getattr(agent, "trust_state", None)
    if trust is not None:  # the record of the predictions the robot checked, as the episode ended
        record["prediction_trust"] = trust.as_dict()
    atomic_write_text(out / "run.json", json.dumps(record, indent=2) + "\n")
    written.append(out / "run.json")
    return result, written


def summary_line(exploration: Exploration, result: EpisodeResult) -> str:
    """The one line `guide explore` ends with: complete or not, distance, waypoints, explored share, timing."""
    status = "complete" if result.complete else f"INCOMPLETE ({result.failure})"
    timing = (
        f"decision {result.metrics_row()['decision_ms_median']} ms median"
        if result.decision_ms
        else "no decision needed (complete at the first scan)"
    )
    return (
        f"{exploration.ground_truth.name} {exploration.label}: {status}, {result.distance_m:.1f} m in "
        f"{result.steps} waypoints, explored {result.explored_ratio * 100:.1f} %, {timing}"
    )


def after_failure(exploration: Exploration, result: EpisodeResult) -> str | None:
    """What to try when the episode ran out of steps (None for any other ending)."""
    if not result.complete and result.failure.startswith("step limit"):
        return step_limit_hint(exploration.ground_truth, exploration.protocol)
    return None
