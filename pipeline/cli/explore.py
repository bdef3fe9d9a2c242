"""`guide explore`: one planner on one map, with its trajectory, metrics, picture and animation."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from pipeline.cli.options import (
    CellSize,
    Checkpoint,
    DoneCells,
    MaxSteps,
    NodeRes,
    RegionSize,
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
from pipeline.planners.matched_models import model_files
from pipeline.workflows import explore as exploration
from pipeline.world.maps import MapError

app = typer.Typer(rich_markup_mode=None)


@app.command()
def explore(
    ctx: typer.Context,
    map_path: Path = typer.Option(..., "--map", help="Maze PNG, ROS map YAML or .npy grid."),
    planner: str = typer.Option(
        "nearest_frontier", help="Planner name (see `guide planners`) or labelled variant label=name:key=value,..."),
    out: Optional[Path] = typer.Option(None, help="Output folder [default: runs/explore/<planner label>]."),
    gif: bool = typer.Option(False, "--gif", help="Also write an animation of the episode."),
    bag: Optional[Path] = typer.Option(
        None, "--bag", help="Also record the episode as MCAP (belief as /map, pose as /tf, plans, graph markers) "
                            "for Foxglove or `ros2 bag play` (pip install '.[robot]')."),
    start: Optional[tuple[float, float]] = Start,
    seed: int = typer.Option(0, min=0, help="Seed for randomised planners."),
    checkpoint: Optional[Path] = Checkpoint,
    cell_size: float = CellSize, node_resolution: float = NodeRes, sensor_range: float = SensorRange,
    utility_range: Optional[float] = UtilityRange, region_size: Optional[float] = RegionSize,
    done_unknown_cells: int = DoneCells, max_steps: int = MaxSteps,
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar on stderr."),
) -> None:
    """Explore one map with one planner: trajectory CSV, metrics, final PNG (and GIF), run.json."""
    rules = protocol(cell_size, node_resolution, sensor_range, utility_range, region_size, done_unknown_cells, max_steps)
    try:
        run = exploration.prepare(map_path, planner, rules, out, start, checkpoint)
    except (MapError, ValueError, FileNotFoundError, TypeError) as error:  # an unknown planner name is a ValueError too
        fail(str(error))
    ground_truth = run.ground_truth
    if exploration.is_ros_map(map_path) and given(ctx, "cell_size") and abs(cell_size - ground_truth.cell_size) > 1e-12:
        warn(f"{map_path.name} carries its own resolution ({ground_truth.cell_size:g} m per cell); --cell-size is ignored")
    check_out_dir(run.out)  # before the episode: a long run is not lost to an unwritable folder
    if bag is not None:
        check_bag_out(bag)
    for problem in run.problems:
        warn(problem)
    run.planner.check_protocol(run.protocol)  # before the progress bar, which a warning from inside the episode would cut
    typer.echo(f"{run.label}: {run.planner.description}")
    files = model_files(run.planner)
    if files:
        typer.echo(f"models: {', '.join(files)}")
    result, written = exploration.run(run, seed=seed, gif=gif, progress=progress, start=start, bag=bag)
    typer.echo(exploration.summary_line(run, result))
    typer.echo("wrote " + ", ".join(str(path) for path in written))
    if not result.complete:
        hint = exploration.after_failure(run, result)
        if hint:
            warn(hint)
        raise typer.Exit(code=1)
