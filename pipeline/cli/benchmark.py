"""`guide benchmark`: every map of a folder with each planner, in parallel, summarised and logged."""

from __future__ import annotations

from pathlib import Path
from typing import NoReturn, Optional

import typer

from pipeline.cli.options import (
    CellSize,
    Checkpoint,
    DoneCells,
    DoorGraph,
    MaxSteps,
    NodeRes,
    RegionSize,
    RobotRadius,
    SensorRange,
    UtilityRange,
    check_out_dir,
    fail,
    protocol,
    warn,
)
from pipeline.evaluation.benchmark import BenchmarkInterrupted, EpisodeErrors
from pipeline.evaluation.exploration_curves import PAPER_SPEED_MPS, SpeedModel
from pipeline.evaluation.team_benchmark import TEAM_METRICS_CSV, check_comm_range, check_robot_counts
from pipeline.reporting.benchmark_markdown import team_summary_markdown
from pipeline.workflows.benchmark import benchmark_folder, team_benchmark_folder
from pipeline.world.map_files import MapError
from pipeline.world.protocol import Protocol
from pipeline.world.team import MAX_ROBOTS

app = typer.Typer(rich_markup_mode=None)


@app.command()
def benchmark(
    maps: Path = typer.Option(..., help="Folder of maps (maze PNGs, .npy grids, ROS YAMLs)."),
    planner: list[str] = typer.Option(
        ..., "--planner", help="Planner name or labelled variant label=name:key=value,...; repeat for several."
    ),
    out: Path = typer.Option(Path("runs/bench"), help="Output folder (trajectories, metrics.csv, summary.md)."),
    workers: Optional[int] = typer.Option(None, min=1, help="Parallel processes [default: all cores]."),
    backend: Optional[str] = typer.Option(
        None,
        help="Where the episodes run: process (this machine's cores) or ray (the Ray cluster $RAY_ADDRESS "
        "names, else a private one here) [default: $GUIDE_BACKEND or process].",
    ),
    seed: int = typer.Option(0, min=0, help="Seed for randomised planners."),
    tracking_uri: Optional[str] = typer.Option(
        None, help="MLflow store [default: $MLFLOW_TRACKING_URI or sqlite:///mlflow.db]."
    ),
    experiment: str = typer.Option("benchmark", help="MLflow experiment name."),
    mlflow_log: bool = typer.Option(True, "--mlflow/--no-mlflow", help="Log one MLflow run per planner."),
    checkpoint: Optional[Path] = Checkpoint,
    baseline: Optional[str] = typer.Option(
        None,
        help="Label to compare every planner with, map by map, in summary.md ('' for none) "
        "[default: greedy_utility when it runs].",
    ),
    start: Optional[tuple[float, float]] = typer.Option(
        None,
        help="One start for every map, as in `explore` (needed for .npy grids and ROS maps without 'start'): "
        "COL ROW cells for maze PNGs and .npy grids, X Y metres for ROS maps, so keep each kind in its own folder.",
    ),
    cell_size: float = CellSize,
    node_resolution: float = NodeRes,
    sensor_range: float = SensorRange,
    utility_range: Optional[float] = UtilityRange,
    region_size: Optional[float] = RegionSize,
    done_unknown_cells: int = DoneCells,
    max_steps: int = MaxSteps,
    robot_radius: float = RobotRadius,
    door_graph: Optional[bool] = DoorGraph,
    speed_mps: float = typer.Option(
        PAPER_SPEED_MPS,
        help="The robot's speed for exploration time and the "
        "per-second efficiency (m/s) [default: the paper's maximum].",
    ),
    robots: Optional[list[int]] = typer.Option(
        None,
        "--robots",
        help=f"Run teams of this many robots (1-{MAX_ROBOTS}; repeat for several counts) instead of "
        "one robot: the team benchmark, written to OUT/<label>@<robots>/ and OUT/team_*.",
    ),
    comm_range: Optional[float] = typer.Option(
        None,
        "--comm-range",
        help="With --robots: robots merge what they know only within this many metres of "
        "each other (or through a chain of robots that are) [default: full communication].",
    ),
) -> None:
    """Run every map in a folder with each planner, in parallel, and summarise.

    Writes per planner OUT/<label>/<map>.csv (the trajectory) and <map>.steps.csv (the per-step
    record), and OUT/metrics.csv, summary.md, exploration.csv (distance to 50 / 90 / 99 % of the
    free area, coverage AUC, Table V efficiency), coverage.png and run.json.

    With --robots N (repeatable), teams of N robots instead: per planner and count OUT/<label>@<N>/
    with <map>.team.csv (the team trajectory), <map>.robots.csv and, under --comm-range,
    <map>.team.merges.csv; and OUT/team_metrics.csv, team_coverage.csv, team_summary.json,
    team_coverage.png and team_run.json.

    Each finished episode is kept (OUT/.episodes/, OUT/.team_episodes/) until the run completes:
    killed, the same command resumes it. Exits 1 when an episode did not complete (the files are
    written either way).
    """
    try:
        speed = SpeedModel(speed_mps)
    except ValueError as error:
        fail(f"--speed-mps: {error}")
    if robots:
        try:
            counts = check_robot_counts(robots)
        except ValueError:
            fail(f"--robots takes team sizes 1-{MAX_ROBOTS}, got {', '.join(str(n) for n in robots)}")
        try:
            comm_range_m = check_comm_range(comm_range)
        except ValueError:
            fail(f"--comm-range takes a positive number of metres, got {comm_range:g}")
        if baseline is not None:
            fail("--baseline compares single-robot planners in summary.md; a team benchmark (--robots) has none")
    elif comm_range is not None:
        fail("--comm-range is the range of a team's radios: give the team size with --robots")
    check_out_dir(out)
    rules = protocol(
        cell_size,
        node_resolution,
        sensor_range,
        utility_range,
        region_size,
        done_unknown_cells,
        max_steps,
        robot_radius,
        door_graph,
    )
    if robots:
        team_benchmark_command(
            maps,
            list(planner),
            rules,
            out,
            counts,
            comm_range_m,
            workers=workers,
            seed=seed,
            start=start,
            checkpoint=checkpoint,
            tracking_uri=tracking_uri,
            experiment=experiment,
            mlflow=mlflow_log,
            speed=speed,
            backend=backend,
        )
        return
    try:
        run = benchmark_folder(
            maps,
            list(planner),
            rules,
            out,
            workers=workers,
            seed=seed,
            baseline=baseline,
            start=start,
            checkpoint=checkpoint,
            tracking_uri=tracking_uri,
            experiment=experiment,
            mlflow=mlflow_log,
            warn=warn,
            speed=speed,
            backend=backend,
        )
    except BenchmarkInterrupted as stop:
        stop_interrupted(stop, "episodes", f"{out}/metrics.csv and summary.md hold them")
    except (MapError, ValueError, FileNotFoundError) as error:  # a malformed spec, an unknown option or name, no model
        fail(str(error))
    frame = run.frame
    typer.echo((out / "summary.md").read_text(), nl=False)
    typer.echo(
        f"wrote {out}/metrics.csv, summary.md, exploration.csv, coverage.png, run.json and {len(frame)} "
        f"trajector{'ies' if len(frame) != 1 else 'y'} with their per-step files"
    )
    stop_on_planner_errors(run.errors, out)
    incomplete = int((~frame["complete"].astype(bool)).sum())
    if incomplete:
        typer.echo(f"{incomplete} of {len(frame)} episodes did not complete (see summary.md)", err=True)
        raise typer.Exit(code=1)


def stop_on_planner_errors(errors: list[tuple[str, str, str]], out: Path) -> None:
    """Exit 1 listing the episodes whose planner raised (map, planner, error), when any did."""
    if errors:
        typer.echo(str(EpisodeErrors(errors, out)), err=True)
        raise typer.Exit(code=1)


def stop_interrupted(stop: BenchmarkInterrupted, episodes: str, kept: str) -> NoReturn:
    """Exit 130 after Ctrl-C, saying how many `episodes` were done, where they are (`kept`, when
    any were) and that the same command resumes."""
    where = f"; {kept}" if stop.done else ""
    typer.echo(
        f"interrupted after {stop.done} of {stop.total} {episodes}{where}; the same command resumes the run", err=True
    )
    raise typer.Exit(code=130)


def team_benchmark_command(
    maps: Path,
    planners: list[str],
    rules: Protocol,
    out: Path,
    robots: list[int],
    comm_range_m: Optional[float],
    **options,
) -> None:
    """The team benchmark of `guide benchmark --robots`: run, summary printed, exit 1 when an episode did not complete."""
    try:
        run = team_benchmark_folder(maps, planners, rules, out, robots, comm_range_m=comm_range_m, warn=warn, **options)
    except BenchmarkInterrupted as stop:
        stop_interrupted(stop, "team episodes", f"{out}/{TEAM_METRICS_CSV} holds them")
    except (MapError, ValueError, FileNotFoundError) as error:  # a malformed spec, an unknown option or name, no model
        fail(str(error))
    frame = run.frame
    typer.echo(team_summary_markdown(run.summary), nl=False)
    typer.echo(
        f"wrote {out}/{TEAM_METRICS_CSV}, team_coverage.csv, team_summary.json, team_coverage.png, "
        f"team_run.json and {len(frame)} team trajector{'ies' if len(frame) != 1 else 'y'} "
        "with their per-robot files"
    )
    stop_on_planner_errors(run.errors, out)
    incomplete = int((~frame["complete"].astype(bool)).sum())
    if incomplete:
        for row in frame[~frame["complete"].astype(bool)].itertuples():
            failure = next(
                result.failure
                for task, result in run.episodes
                if task.run_label == row.label and result.map_name == row.map
            )
            typer.echo(f"{row.label} on {row.map}: {failure or 'incomplete'}", err=True)
        typer.echo(f"{incomplete} of {len(frame)} team episodes did not complete", err=True)
        raise typer.Exit(code=1)
