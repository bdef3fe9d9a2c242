"""`guide benchmark`: every map of a folder with each planner, in parallel, summarised and logged."""

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
    UtilityRange,
    check_out_dir,
    fail,
    protocol,
    warn,
)
from pipeline.evaluation.benchmark import BenchmarkInterrupted
from pipeline.evaluation.exploration_curves import PAPER_SPEED_MPS, SpeedModel
from pipeline.workflows.benchmark import benchmark_folder
from pipeline.world.maps import MapError

app = typer.Typer(rich_markup_mode=None)


@app.command()
def benchmark(
    maps: Path = typer.Option(..., help="Folder of maps (maze PNGs, .npy grids, ROS YAMLs)."),
    planner: list[str] = typer.Option(
        ..., "--planner", help="Planner name or labelled variant label=name:key=value,...; repeat for several."),
    out: Path = typer.Option(Path("runs/bench"), help="Output folder (trajectories, metrics.csv, summary.md)."),
    workers: Optional[int] = typer.Option(None, min=1, help="Parallel processes [default: all cores]."),
    backend: Optional[str] = typer.Option(
        None, help="Where the episodes run: process (this machine's cores) or ray (the Ray cluster $RAY_ADDRESS "
                   "names, else a private one here) [default: $GUIDE_BACKEND or process]."),
    seed: int = typer.Option(0, min=0, help="Seed for randomised planners."),
    tracking_uri: Optional[str] = typer.Option(None, help="MLflow store [default: $MLFLOW_TRACKING_URI or sqlite:///mlflow.db]."),
    experiment: str = typer.Option("benchmark", help="MLflow experiment name."),
    mlflow_log: bool = typer.Option(True, "--mlflow/--no-mlflow", help="Log one MLflow run per planner."),
    checkpoint: Optional[Path] = Checkpoint,
    baseline: Optional[str] = typer.Option(
        None, help="Label to compare every planner with, map by map, in summary.md ('' for none) "
                   "[default: greedy_utility when it runs]."),
    start: Optional[tuple[float, float]] = typer.Option(
        None, help="One start for every map, as in `explore` (needed for .npy grids and ROS maps without 'start'): "
                   "COL ROW cells for maze PNGs and .npy grids, X Y metres for ROS maps, so keep each kind in its own folder."),
    cell_size: float = CellSize, node_resolution: float = NodeRes, sensor_range: float = SensorRange,
    utility_range: Optional[float] = UtilityRange, region_size: Optional[float] = RegionSize,
    done_unknown_cells: int = DoneCells, max_steps: int = MaxSteps,
    speed_mps: float = typer.Option(PAPER_SPEED_MPS, help="The robot's speed for exploration time and the "
                                                          "per-second efficiency (m/s) [default: the paper's maximum]."),
) -> None:
    """Run every map in a folder with each planner, in parallel, and summarise.

    Writes per planner OUT/<label>/<map>.csv (the trajectory) and <map>.steps.csv (the per-step
    record), and OUT/metrics.csv, summary.md, exploration.csv (distance to 50 / 90 / 99 % of the
    free area, coverage AUC, Table V efficiency), coverage.png and run.json.

    Each finished episode is kept (OUT/.episodes/) until the run completes: killed, the same
    command resumes it. Exits 1 when an episode did not complete (the files are written either way).
    """
    try:
        speed = SpeedModel(speed_mps)
    except ValueError as error:
        fail(f"--speed-mps: {error}")
    check_out_dir(out)
    rules = protocol(cell_size, node_resolution, sensor_range, utility_range, region_size, done_unknown_cells, max_steps)
    try:
        frame = benchmark_folder(maps, list(planner), rules, out, workers=workers, seed=seed, baseline=baseline,
                                 start=start, checkpoint=checkpoint, tracking_uri=tracking_uri,
                                 experiment=experiment, mlflow=mlflow_log, warn=warn,
                                 speed=speed, backend=backend).frame
    except BenchmarkInterrupted as stop:
        kept = f"; {out}/metrics.csv and summary.md hold them" if stop.done else ""
        typer.echo(f"interrupted after {stop.done} of {stop.total} episodes{kept}; the same command resumes "
                   "the run", err=True)
        raise typer.Exit(code=130)
    except (MapError, ValueError, FileNotFoundError) as error:  # a malformed spec, an unknown option or name, no model
        fail(str(error))
    typer.echo((out / "summary.md").read_text(), nl=False)
    typer.echo(f"wrote {out}/metrics.csv, summary.md, exploration.csv, coverage.png, run.json and {len(frame)} "
               f"trajector{'ies' if len(frame) != 1 else 'y'} with their per-step files")
    incomplete = int((~frame["complete"].astype(bool)).sum())
    if incomplete:
        typer.echo(f"{incomplete} of {len(frame)} episodes did not complete (see summary.md)", err=True)
        raise typer.Exit(code=1)
