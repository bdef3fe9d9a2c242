"""`guide explore`: one planner on one map, with its trajectory, metrics, picture and animation;
with `--robots N`, a team of N robots running the planner's team version."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Optional

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
    Start,
    UtilityRange,
    check_bag_out,
    check_out_dir,
    fail,
    given,
    protocol,
    warn,
)
from pipeline.evaluation.exploration_curves import PAPER_SPEED_MPS, SpeedModel
from pipeline.evaluation.team_benchmark import check_comm_range
from pipeline.planners.matched_models import model_files
from pipeline.workflows import explore as exploration
from pipeline.world.map_files import MapError
from pipeline.world.protocol import Protocol
from pipeline.world.team import MAX_ROBOTS

app = typer.Typer(rich_markup_mode=None)


@app.command()
def explore(
    ctx: typer.Context,
    map_path: Path = typer.Option(..., "--map", help="Maze PNG, ROS map YAML or .npy grid."),
    planner: str = typer.Option(
        "nearest_frontier", help="Planner name (see `guide planners`) or labelled variant label=name:key=value,..."
    ),
    out: Optional[Path] = typer.Option(None, help="Output folder [default: runs/explore/<planner label>]."),
    gif: bool = typer.Option(False, "--gif", help="Also write an animation of the episode."),
    bag: Optional[Path] = typer.Option(
        None,
        "--bag",
        help="Also record the episode as MCAP (belief as /map, pose as /tf, plans, graph markers) "
        "for Foxglove or `ros2 bag play` (pip install '.[robot]').",
    ),
    start: Optional[tuple[float, float]] = Start,
    seed: int = typer.Option(0, min=0, help="Seed for randomised planners."),
    checkpoint: Optional[Path] = Checkpoint,
    cell_size: float = CellSize,
    node_resolution: float = NodeRes,
    sensor_range: float = SensorRange,
    utility_range: Optional[float] = UtilityRange,
    region_size: Optional[float] = RegionSize,
    done_unknown_cells: int = DoneCells,
    max_steps: int = MaxSteps,
    robot_radius: float = RobotRadius,
    door_graph: Optional[bool] = DoorGraph,
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar on stderr."),
    robots: Optional[int] = typer.Option(
        None,
        "--robots",
        help=f"Explore with a team of this many robots (1-{MAX_ROBOTS}) running the planner's team "
        "version, all from the start [default: one robot, the single-robot episode].",
    ),
    comm_range: Optional[float] = typer.Option(
        None,
        "--comm-range",
        help="With --robots: robots merge what they know only within this many metres of "
        "each other (or through a chain of robots that are) [default: full communication].",
    ),
    speed_mps: float = typer.Option(
        PAPER_SPEED_MPS,
        help="With --robots: the robots' speed (m/s) for the team file's times (the paper's "
        "maximum, as in the team benchmark).",
    ),
) -> None:
    """Explore one map with one planner: trajectory CSV, metrics, final PNG (and GIF), run.json.

    With --robots N, a team of N robots instead: OUT (default runs/explore/<label>@<N>) gets
    <map>.team.csv, <map>.robots.csv, under --comm-range <map>.team.merges.csv, team_metrics.csv,
    <map>.png (each robot's path in its colour), with --gif <map>.gif, and run.json.
    """
    if robots is not None:
        if bag is not None:
            fail("--bag records one robot's episode; it is not supported for teams (drop --bag or --robots)")
        if not 1 <= robots <= MAX_ROBOTS:
            fail(f"--robots takes a team size 1-{MAX_ROBOTS}, got {robots}")
        try:
            check_comm_range(comm_range)
        except ValueError:
            fail(f"--comm-range takes a positive number of metres, got {comm_range:g}")
        try:
            speed = SpeedModel(speed_mps)
        except ValueError as error:
            fail(f"--speed-mps: {error}")
    elif comm_range is not None:
        fail("--comm-range is the range of a team's radios: give the team size with --robots")
    elif given(ctx, "speed_mps"):
        fail("--speed-mps sets a team file's times: give the team size with --robots")
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
    if robots is not None:
        explore_team(
            ctx,
            map_path,
            planner,
            rules,
            robots,
            comm_range,
            speed,
            out=out,
            gif=gif,
            start=start,
            seed=seed,
            checkpoint=checkpoint,
            cell_size=cell_size,
            progress=progress,
        )
        return
    try:
        run = exploration.prepare(map_path, planner, rules, out, start, checkpoint)
    except (MapError, ValueError, FileNotFoundError, TypeError) as error:  # an unknown planner name is a ValueError too
        fail(str(error))
    if bag is not None:
        check_bag_out(bag)
    before_episode(ctx, map_path, run, cell_size)
    typer.echo(f"{run.label}: {run.planner.description}")
    files = model_files(run.planner)
    if files:
        typer.echo(f"models: {', '.join(files)}")
    result, written = exploration.run(run, seed=seed, gif=gif, progress=progress, start=start, bag=bag)
    after_episode(
        exploration.summary_line(run, result), written, result.complete, lambda: exploration.after_failure(run, result)
    )


def before_episode(ctx: typer.Context, map_path: Path, run: Any, cell_size: float) -> None:
    """What is said and checked before an episode (one robot's or a team's): a ROS map's own
    resolution over --cell-size, the output folder (a long run is not lost to an unwritable one),
    why the map may not complete, and models trained at other protocol values (before the progress
    bar, which a warning from inside the episode would cut)."""
    if (
        exploration.is_ros_map(map_path)
        and given(ctx, "cell_size")
        and abs(cell_size - run.ground_truth.cell_size) > 1e-12
    ):
        warn(
            f"{map_path.name} carries its own resolution ({run.ground_truth.cell_size:g} m per cell); --cell-size is ignored"
        )
    check_out_dir(run.out)
    for problem in run.problems:
        warn(problem)
    run.planner.check_protocol(run.protocol)


def after_episode(summary: str, written: list[Path], complete: bool, hint: Callable[[], Optional[str]]) -> None:
    """The summary line and the files written; exit 1, with what to try, when the episode did not complete."""
    typer.echo(summary)
    typer.echo("wrote " + ", ".join(str(path) for path in written))
    if not complete:
        text = hint()
        if text:
            warn(text)
        raise typer.Exit(code=1)


def explore_team(
    ctx: typer.Context,
    map_path: Path,
    planner: str,
    rules: Protocol,
    robots: int,
    comm_range: Optional[float],
    speed: SpeedModel,
    *,
    out: Optional[Path],
    gif: bool,
    start: Optional[tuple[float, float]],
    seed: int,
    checkpoint: Optional[Path],
    cell_size: float,
    progress: bool,
) -> None:
    """`guide explore --robots N`: one team episode, its files, a summary line; exit 1 when it did not complete."""
    try:
        run = exploration.prepare_team(map_path, planner, rules, robots, comm_range, out, start, checkpoint)
    except (MapError, ValueError, FileNotFoundError, TypeError) as error:  # an unknown planner name is a ValueError too
        fail(str(error))
    before_episode(ctx, map_path, run, cell_size)
    range_text = "full communication" if run.comm_range_m is None else f"{run.comm_range_m:g} m range"
    typer.echo(f"{run.label}: {run.planner.description} ({robots} robot{'s' if robots != 1 else ''}, {range_text})")
    result, written = exploration.run_team(run, seed=seed, gif=gif, progress=progress, start=start, speed=speed)
    after_episode(
        exploration.team_summary_line(run, result),
        written,
        result.complete,
        lambda: exploration.after_failure(run, result),
    )
