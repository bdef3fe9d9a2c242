"""Explore one map and write what `guide explore` shows, with one planner (`prepare`, `run`) or a team
(`prepare_team`, `run_team`), and run.json saying what ran.

One robot: the trajectory CSV, its per-step record, metrics, the final picture (and an animation).
A team: the files of one run of the team benchmark (`pipeline.evaluation.team_benchmark`), written by
its own writers so that `guide replay` and the team figures read them alike (the team trajectory at
the speed model's speed, its merges under a range, the per-robot table, a one-row team_metrics.csv),
the final paths picture (and an animation)."""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import pandas as pd
from tqdm import tqdm

from pipeline.common.atomic import atomic_file, atomic_write_text
from pipeline.evaluation.benchmark import with_policy_checkpoint
from pipeline.evaluation.exploration_curves import SpeedModel
from pipeline.evaluation.map_checks import before_episodes, step_limit_hint
from pipeline.evaluation.team_benchmark import (
    METRICS_COLUMNS,
    TEAM_METRICS_CSV,
    check_comm_range,
    check_robot_counts,
    resolve_team_specs,
    team_run_label,
    write_team_files,
)
from pipeline.planners.specs import as_specs, build_planner, resolve_planner_specs
from pipeline.planners.team.registry import team_config
from pipeline.planners.wrapper import innermost
from pipeline.reporting.panels import render_final
from pipeline.reporting.recorder import EpisodeRecorder
from pipeline.reporting.team_figures import team_animation, team_paths_figure
from pipeline.robot.recording import EpisodeRecording
from pipeline.world.maps import GroundTruthMap, load_map
from pipeline.world.planner import Planner
from pipeline.world.protocol import Protocol, protocol_for_map
from pipeline.world.simulator import EpisodeResult, final_belief, run_episode
from pipeline.world.team import TeamEpisode, TeamEpisodeResult, TeamPlanner, run_team_episode
from pipeline.world.trajectories import steps_path, write_metrics_csv, write_steps_csv, write_trajectory_csv

DEFAULT_OUT = Path("runs/explore")
GIF_FRAMES = 40  # evenly spaced team times: enough to follow the robots, small enough to write quickly


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
    ground_truth, protocol = loaded_map(map_path, protocol, start)
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


def loaded_map(
    map_path: Path, protocol: Protocol, start: tuple[float, float] | None
) -> tuple[GroundTruthMap, Protocol]:
    """The map and the protocol it runs under (a ROS map brings its own cell size)."""
    ground_truth = load_map(map_path, start=start, cell_size=protocol.cell_size)
    return ground_truth, protocol_for_map(protocol, ground_truth, map_path)


def is_ros_map(path: Path) -> bool:
    return path.suffix.lower() in (".yaml", ".yml")


def explored_bar(name: str, progress: bool) -> tqdm:
    """The progress bar of an episode: the explored share, its text set as the episode goes."""
    return tqdm(
        total=100.0,
        desc=f"{name}: explored",
        disable=not progress,
        leave=False,
        bar_format="{desc} {percentage:3.0f}%|{bar}|",
    )


def write_run_json(
    out: Path, exploration: "Exploration | TeamExploration", label: str, seed: int, start, **settings
) -> Path:
    """OUT/run.json: the map, start, seed, the planner (label, name, options, description), the
    `settings` of a team run, and the protocol."""
    record = {
        "map": str(exploration.map_path),
        "start": list(start) if start is not None else None,
        "seed": seed,
        "planner": {
            "label": label,
            "name": exploration.name,
            "options": exploration.options,
            "description": exploration.planner.description,
        },
        **settings,
        "protocol": exploration.protocol.to_dict(),
    }
    atomic_write_text(out / "run.json", json.dumps(record, indent=2) + "\n")
    return out / "run.json"


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
    with explored_bar(ground_truth.name, progress) as bar:

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
    trust = getattr(agent, "trust_state", None)  # the record of the predictions the robot checked, at the end
    extra = {"prediction_trust": trust.as_dict()} if trust is not None else {}
    written.append(write_run_json(out, exploration, exploration.label, seed, start, **extra))
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


def after_failure(
    exploration: "Exploration | TeamExploration", result: "EpisodeResult | TeamEpisodeResult"
) -> str | None:
    """What to try when the episode (a robot of the team) ran out of steps (None for any other ending)."""
    if not result.complete and result.failure.startswith("step limit"):
        return step_limit_hint(exploration.ground_truth, exploration.protocol)
    return None


@dataclass
class TeamExploration:
    """One team planner on one map, before the episode runs: everything checked and built."""

    map_path: Path
    ground_truth: GroundTruthMap
    protocol: Protocol  # the map's own cell size for a ROS map
    label: str  # the run's, `<spec label>@<robots>`
    spec_label: str
    name: str
    options: dict
    planner: TeamPlanner
    robots: int
    comm_range_m: float | None
    out: Path
    problems: list[str] = field(default_factory=list)  # why the map may not complete, said before the episode


def prepare_team(
    map_path: Path,
    planner: str,
    protocol: Protocol,
    robots: int,
    comm_range_m: float | None = None,
    out: Path | None = None,
    start: tuple[float, float] | None = None,
    checkpoint: Path | None = None,
) -> TeamExploration:
    """Check the robot count and range, load the map, build the spec's team planner and check the
    map, before any work (ValueError, MapError, FileNotFoundError in one line)."""
    (robots,) = check_robot_counts([robots])
    comm_range_m = check_comm_range(comm_range_m)
    ground_truth, protocol = loaded_map(map_path, protocol, start)
    ((spec, agent),) = resolve_team_specs(
        with_policy_checkpoint(as_specs([planner]), checkpoint, config_of=team_config)
    )
    problems, _ = before_episodes(ground_truth, protocol, scan_for_unobservable=True)
    label = team_run_label(spec.label, robots)
    return TeamExploration(
        Path(map_path),
        ground_truth,
        protocol,
        label,
        spec.label,
        spec.name,
        dict(spec.options),
        agent,
        robots,
        comm_range_m,
        out if out is not None else DEFAULT_OUT / label,
        problems,
    )


def run_team(
    exploration: TeamExploration,
    seed: int = 0,
    gif: bool = False,
    progress: bool = True,
    start: tuple[float, float] | None = None,
    speed: SpeedModel = SpeedModel(),
) -> tuple[TeamEpisodeResult, list[Path]]:
    """Run the team episode with a progress bar (explored share, team time) and write its files;
    (the result, the files written). Every robot starts at the map's start, as in the team benchmark."""
    ground_truth, protocol, out = exploration.ground_truth, exploration.protocol, exploration.out
    with explored_bar(ground_truth.name, progress) as bar:

        def on_event(episode: TeamEpisode) -> None:
            share = episode.union.free_count / max(1, ground_truth.free_cell_count)
            bar.n = round(100.0 * share, 1)
            bar.set_description_str(
                f"{ground_truth.name}: {exploration.robots} robots, team time {episode.time:.0f} m, explored",
                refresh=True,
            )

        result = run_team_episode(
            ground_truth,
            exploration.planner,
            protocol,
            exploration.robots,
            comm_range_m=exploration.comm_range_m,
            seed=seed,
            on_event=on_event,
        )
    result.map_name = ground_truth.name
    name = ground_truth.name
    written = write_team_files(result, out, exploration.comm_range_m is not None, speed)
    with atomic_file(out / TEAM_METRICS_CSV) as tmp:
        pd.DataFrame([{**result.metrics_row(), "label": exploration.label}], columns=METRICS_COLUMNS).to_csv(
            tmp, index=False
        )
    written.append(out / TEAM_METRICS_CSV)
    title = team_title(exploration, result)
    team_paths_figure(ground_truth, result.rows, protocol, out / f"{name}.png", title)
    written.append(out / f"{name}.png")
    if gif:
        written.append(
            team_animation(
                ground_truth,
                result.rows,
                protocol,
                out / f"{name}.gif",
                frames=GIF_FRAMES,
                title=f"map {name}  |  {exploration.label}",
            )
        )
    written.append(
        write_run_json(
            out,
            exploration,
            exploration.spec_label,
            seed,
            start,
            robots=exploration.robots,
            comm_range_m=exploration.comm_range_m,
            speed_mps=speed.speed_mps,
        )
    )
    return result, written


def team_title(exploration: TeamExploration, result: TeamEpisodeResult) -> str:
    """The final picture's title: map, run, makespan, total distance, complete or not."""
    status = "complete" if result.complete else "incomplete"
    range_text = "" if exploration.comm_range_m is None else f"  |  range {exploration.comm_range_m:g} m"
    return (
        f"map {result.map_name}  |  {exploration.label}{range_text}  |  makespan {result.makespan_m:.1f} m  |  "
        f"total {result.total_distance_m:.1f} m  |  {status}"
    )


def team_summary_line(exploration: TeamExploration, result: TeamEpisodeResult) -> str:
    """The one line `guide explore --robots` ends with: complete or not, makespan, total and
    per-robot distances, median decision time."""
    status = "complete" if result.complete else f"INCOMPLETE ({result.failure})"
    per_robot = ", ".join(f"{distance:.1f}" for distance in result.robot_distance_m)
    median = result.metrics_row()["decision_ms_median"]
    timing = (
        f"decision {median} ms median" if any(result.decision_ms) else "no decision needed (complete at the first scan)"
    )
    return (
        f"{exploration.ground_truth.name} {exploration.label}: {status}, makespan {result.makespan_m:.1f} m, "
        f"total {result.total_distance_m:.1f} m (robots {per_robot} m), explored "
        f"{result.explored_ratio * 100:.1f} %, {timing}"
    )
