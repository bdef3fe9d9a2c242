"""The `guide` command line: every pipeline stage and the everyday verbs."""

from __future__ import annotations

import json
import math
import re
import sys
import tempfile
import warnings
from pathlib import Path
from typing import Optional

import typer

from pipeline.world.maps import MapError
from pipeline.world.protocol import Protocol

app = typer.Typer(
    help="GUIDE exploration: maps, simulator, planners, benchmarks and the DVC pipeline's stages.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help texts hold literal brackets: [default: ...], '.[ray]'
)
stage_app = typer.Typer(help="Run one DVC pipeline stage (what `dvc repro` calls).", no_args_is_help=True,
                        rich_markup_mode=None)
app.add_typer(stage_app, name="stage")


def _warning_line(message, category, filename, lineno, line=None) -> str:
    return f"warning: {message}\n"


@app.callback()
def _console(ctx: typer.Context) -> None:
    # A command line user gets a warning as one line, as errors are, not Python's file:line + source;
    # the usual format comes back when the command ends (the CLI may run inside another program).
    previous = warnings.formatwarning
    warnings.formatwarning = _warning_line
    ctx.call_on_close(lambda: setattr(warnings, "formatwarning", previous))


def _fail(message: str) -> None:
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(code=2)


def _check_params(params: Path) -> None:
    if not params.is_file():
        _fail(f"{params}: no parameters file (run from the project folder, or pass --params PATH)")


def _run_stage(main, params: Path, *args) -> None:
    """A stage's main(params, ...); a missing params file or upstream output, a bad setting, is one
    error line (exit 2), as `python -m stages.<name>` prints it (`pipeline.stage_errors`)."""
    from pipeline.stage_errors import user_error_message

    _check_params(params)
    try:
        main(str(params), *args)
    except (Exception, SystemExit) as error:
        message = user_error_message(error)
        if message is None:
            raise
        _fail(message)


def _check_backend(backend: Optional[str]) -> None:
    if backend not in (None, "process", "ray"):
        _fail(f"--backend {backend!r}: choose process or ray")


def _check_out_dir(out: Path) -> None:
    """Fail before any work when --out names something other than a folder, or one that cannot be
    made or written (a file on its path, a read-only disk); the folder exists afterwards."""
    if out.exists() and not out.is_dir():
        _fail(f"{out}: exists and is not a folder; --out takes a folder (created if missing)")
    try:
        out.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=out).close()
    except OSError as error:
        _fail(f"{out}: cannot create or write the output folder ({error.strerror or error})")


def _warn(message: str) -> None:
    typer.echo(f"warning: {message}", err=True)


def _warn_unreachable(ground_truth, protocol: Protocol) -> bool:
    """A map whose free cells beyond the start's reach outnumber the done rule's slack can never
    complete; True when that was warned about."""
    from pipeline.evaluation.benchmark import unreachable_free_cells

    cut_off = unreachable_free_cells(ground_truth)
    if cut_off > protocol.done_unknown_cells:
        _warn(f"{ground_truth.name}: {cut_off} free cells are not connected to the start, more than "
              f"done_unknown_cells={protocol.done_unknown_cells}: no planner can complete this map "
              "(erase stray free pixels outside the walls, or raise --done-unknown-cells)")
    return cut_off > protocol.done_unknown_cells


def _warn_fine_map(ground_truth, protocol: Protocol) -> None:
    """A map so fine that the lidar's neighbouring rays skip cells at full range explores badly
    (README, "Your own SLAM maps"): point at resample-map."""
    from pipeline.world.sensor import DEFAULT_ANGLES

    gap_cells = protocol.sensor_range * float(DEFAULT_ANGLES[1] - DEFAULT_ANGLES[0]) / ground_truth.cell_size
    if gap_cells > 1.0:
        _warn(f"{ground_truth.name} is drawn at {ground_truth.cell_size:g} m per cell: the lidar's rays pass "
              f"{gap_cells:.1f} cells apart at {protocol.sensor_range:g} m and leave holes that read as frontier; "
              "`guide resample-map --map MAP --out OUT.yaml` writes it on the benchmark's 0.4 m grid")


def _warn_unobservable(ground_truth, protocol: Protocol) -> None:
    """Scans on the ground truth from every reachable lattice node: warn when the free cells none of
    them reveals outnumber the done rule's slack (a fine SLAM map's clutter and ragged walls do this)."""
    from pipeline.planners.references.coverage import unobservable_free_cells

    hidden = unobservable_free_cells(ground_truth, protocol)
    if hidden > protocol.done_unknown_cells:
        _warn(f"{ground_truth.name}: {hidden} free cells are seen from no lattice node the robot can reach "
              f"(behind clutter, in nooks of the walls), more than done_unknown_cells={protocol.done_unknown_cells}: "
              f"no planner can complete this map (raise --done-unknown-cells above {hidden})")


def _protocol(
    cell_size: float, node_resolution: float, sensor_range: float, utility_range: Optional[float],
    region_size: float, done_unknown_cells: int, max_steps: int,
) -> Protocol:
    try:
        return Protocol(
            cell_size=cell_size,
            node_resolution=node_resolution,
            sensor_range=sensor_range,
            utility_range=utility_range if utility_range is not None else sensor_range / 2,
            region_size=region_size,
            done_unknown_cells=done_unknown_cells,
            max_steps=max_steps,
        )
    except ValueError as error:  # named by the options: "protocol.sensor_range" -> "--sensor-range"
        _fail(re.sub(r"protocol\.(\w+)", lambda m: "--" + m.group(1).replace("_", "-"), str(error)))
        raise  # unreachable; keeps type checkers calm


CellSize = typer.Option(0.4, help="Metres per cell for maze PNGs and .npy grids (a ROS map has its own).")
NodeRes = typer.Option(4.0, help="Node lattice spacing d_n in metres.")
SensorRange = typer.Option(20.0, help="Lidar range in metres.")
UtilityRange = typer.Option(None, help="Frontier-utility range in metres [default: sensor range / 2].")
RegionSize = typer.Option(20.0, help="Side of the fixed regions in metres.")
DoneCells = typer.Option(250, help="Done when ground-truth free minus belief free cells is at most this.")
MaxSteps = typer.Option(500, help="Waypoints before an episode ends as a failure.")


@app.command()
def planners() -> None:
    """List every registered planner name with a one-line description."""
    from pipeline.planners import planner_class, planner_names

    for name in planner_names():
        cls = planner_class(name)
        oracle = " (oracle: sees the ground truth)" if cls.uses_ground_truth else ""
        typer.echo(f"{name:<18} {cls.description}{oracle}")


@app.command()
def mazes(
    out: Path = typer.Option(..., help="Folder to write maze_NNNN.png (office_NNNN.png, cave_NNNN.png) into (created if missing)."),
    count: int = typer.Option(..., min=1, help="How many mazes."),
    seed: int = typer.Option(0, min=0, help="Maze i is drawn from seed sequence [seed, i]."),
    side: float = typer.Option(100.0, help="Side length in metres (for mazes, a multiple of the block size)."),
    kind: str = typer.Option("maze", help="maze: like the benchmark's; office: office floors (thin walls, "
                                          "wide rooms, clutter), a family the sliver gate is also fitted on; "
                                          "cave: rough-walled caves, a family no model is fitted on."),
    cell_size: float = CellSize,
) -> None:
    """Draw mazes like the benchmark's (the pipeline's generator and defaults), office floors or caves, into a folder.

    More maps than the 12 test mazes make a benchmark comparison resolve smaller differences:
    `guide mazes --out runs/mazes --count 50 --seed 7 && guide benchmark --maps runs/mazes ...`.
    """
    from pipeline.world.caves import CaveConfig, generate_cave_set
    from pipeline.world.mazes import MIN_BLOCK_PIXELS, MazeConfig, generate_maze_set
    from pipeline.world.offices import OfficeConfig, generate_office_set

    if kind not in ("maze", "office", "cave"):
        _fail(f"--kind must be maze, office or cave, got {kind!r}")
    if not (math.isfinite(side) and side > 0):
        _fail(f"--side must be a positive number of metres, got {side:g}")
    if kind != "maze":
        config_class, write_set, what = {"office": (OfficeConfig, generate_office_set, "office floor"),
                                         "cave": (CaveConfig, generate_cave_set, "cave")}[kind]
        try:
            family = config_class(side_m=side, cell_size=cell_size)
        except ValueError as error:  # named by this command's words, not the config's fields
            message = str(error).replace(f"{config_class.__name__} needs", f"{what}s need")
            _fail(message.replace("CaveConfig.block_m", "the 4 m block"))
        _check_out_dir(out)
        if out.is_dir() and any(out.glob(f"{kind}_*.png")):
            _fail(f"{out} already holds {kind} PNGs: pick an empty folder, so no old {what} mixes into a set")
        paths = write_set(family, count, out, seed=seed)
        typer.echo(f"wrote {len(paths)} {what}{'s' if len(paths) != 1 else ''} of {side:g} m to {out}")
        return
    try:
        config = MazeConfig(side_m=(side, side), cell_size=cell_size)
    except ValueError as error:  # named by this command's options, not the config's fields
        if "MazeConfig.block_m" in str(error):
            _fail(f"--cell-size {cell_size:g} does not fit the mazes' {MazeConfig.block_m:g} m blocks: a block must be "
                  f"a whole number (at least {MIN_BLOCK_PIXELS}) of half-cells ({cell_size / 2:g} m); 0.2, 0.4 or 0.5 m fit")
        message = re.sub(r"MazeConfig\.side_m \([^)]*\)", f"--side {side:g}", str(error))
        _fail(message.replace("MazeConfig.side_m", "--side").replace("MazeConfig.cell_size", "--cell-size"))
    _check_out_dir(out)  # after the settings: a refused one leaves no folder behind
    stale = sorted(out.glob("maze_*.png")) if out.is_dir() else []
    if stale:
        _fail(f"{out} already holds {len(stale)} maze PNGs: pick an empty folder, so no old maze mixes into a set")
    paths = generate_maze_set(config, count, out, seed=seed)
    typer.echo(f"wrote {len(paths)} maze{'s' if len(paths) != 1 else ''} of {config.side_m[0]:g} m to {out}")


@app.command()
def explore(
    ctx: typer.Context,
    map_path: Path = typer.Option(..., "--map", help="Maze PNG, ROS map YAML or .npy grid."),
    planner: str = typer.Option(
        "nearest_frontier", help="Planner name (see `guide planners`) or labelled variant label=name:key=value,..."),
    out: Optional[Path] = typer.Option(None, help="Output folder [default: runs/explore/<planner label>]."),
    gif: bool = typer.Option(False, "--gif", help="Also write an animation of the episode."),
    start: Optional[tuple[float, float]] = typer.Option(
        None, help="Start: COL ROW cell for a .npy grid or a maze PNG (overrides its marked start), "
                   "X Y metres for a ROS map (else its YAML 'start')."
    ),
    seed: int = typer.Option(0, min=0, help="Seed for randomised planners."),
    checkpoint: Optional[Path] = typer.Option(
        None, help="Trained policy for the diffusion planners (guide, guide_noregion, dare) "
                   "[default: models/ under the current folder, else the shipped one]."),
    cell_size: float = CellSize, node_resolution: float = NodeRes, sensor_range: float = SensorRange,
    utility_range: Optional[float] = UtilityRange, region_size: float = RegionSize,
    done_unknown_cells: int = DoneCells, max_steps: int = MaxSteps,
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar on stderr."),
) -> None:
    """Explore one map with one planner: trajectory CSV, metrics, final PNG (and GIF), run.json."""
    from pipeline.evaluation.benchmark import build_planner, protocol_for_map, resolve_planner_specs
    from pipeline.world.maps import load_map
    from pipeline.reporting.render import EpisodeRecorder, render_final
    from tqdm import tqdm

    from pipeline.world.simulator import run_episode
    from pipeline.world.trajectories import write_metrics_csv, write_trajectory_csv

    protocol = _protocol(cell_size, node_resolution, sensor_range, utility_range, region_size, done_unknown_cells, max_steps)
    try:
        ground_truth = load_map(map_path, start=start, cell_size=cell_size)
        protocol = protocol_for_map(protocol, ground_truth, map_path)
        (spec,) = resolve_planner_specs(_with_checkpoint([planner], checkpoint))
        agent = build_planner(spec)
    except MapError as error:
        _fail(str(error))
    except KeyError as error:
        _fail(str(error.args[0]))
    except (ValueError, FileNotFoundError, TypeError) as error:
        _fail(str(error))
    ros_map = map_path.suffix.lower() in (".yaml", ".yml")
    if ros_map and _given(ctx, "cell_size") and abs(cell_size - ground_truth.cell_size) > 1e-12:
        _warn(f"{map_path.name} carries its own resolution ({ground_truth.cell_size:g} m per cell); --cell-size is ignored")
    out = out if out is not None else Path("runs/explore") / spec.label
    _check_out_dir(out)  # before the episode: a long run is not lost to an unwritable folder
    _warn_fine_map(ground_truth, protocol)
    if not _warn_unreachable(ground_truth, protocol):
        _warn_unobservable(ground_truth, protocol)
    agent.check_protocol(protocol)  # before the progress bar, which a warning from inside the episode would cut
    typer.echo(f"{spec.label}: {agent.description}")
    recorder = EpisodeRecorder(graph_provider=lambda: getattr(agent, "graph", None), label=spec.label,
                               y_up=ros_map) if gif else None
    with tqdm(total=100.0, desc=f"{ground_truth.name}: explored", disable=not progress, leave=False,
              bar_format="{desc} {percentage:3.0f}%|{bar}|") as bar:

        def on_step(episode) -> None:
            bar.n = round(100.0 * episode.explored_ratio, 1)
            bar.set_description_str(f"{ground_truth.name}: {episode.distance:.0f} m, {episode.steps} waypoints, explored",
                                    refresh=True)
            if recorder is not None:
                recorder(episode)

        result = run_episode(ground_truth, agent, protocol, seed=seed, on_step=on_step)
    result.planner = spec.label
    written = [write_trajectory_csv(out / f"{ground_truth.name}.csv", result.trajectory)]
    write_metrics_csv(out / "metrics.csv", [result.metrics_row()])
    written.append(out / "metrics.csv")
    render_final(
        result, ground_truth, _final_belief(ground_truth, result, protocol),
        graph=getattr(agent, "graph", None), path=out / f"{ground_truth.name}.png", y_up=ros_map,
    )
    written.append(out / f"{ground_truth.name}.png")
    if recorder is not None:
        written.append(recorder.save_gif(out / f"{ground_truth.name}.gif"))
    record = {"map": str(map_path), "start": list(start) if start is not None else None, "seed": seed,
              "planner": {"label": spec.label, "name": spec.name, "options": dict(spec.options),
                          "description": agent.description},
              "protocol": protocol.to_dict()}
    (out / "run.json").write_text(json.dumps(record, indent=2) + "\n")
    written.append(out / "run.json")
    status = "complete" if result.complete else f"INCOMPLETE ({result.failure})"
    timing = (f"decision {result.metrics_row()['decision_ms_median']} ms median" if result.decision_ms
              else "no decision needed (complete at the first scan)")
    typer.echo(
        f"{ground_truth.name} {spec.label}: {status}, {result.distance_m:.1f} m in {result.steps} waypoints, "
        f"explored {result.explored_ratio * 100:.1f} %, {timing}"
    )
    typer.echo("wrote " + ", ".join(str(path) for path in written))
    if not result.complete:
        if result.failure.startswith("step limit"):
            _warn(_step_limit_hint(ground_truth, protocol))
        raise typer.Exit(code=1)


def _step_limit_hint(ground_truth, protocol: Protocol) -> str:
    """What to do when a map outgrows `max_steps` (500 waypoints suit the benchmark's 100 m mazes)."""
    rows, cols = ground_truth.free.shape
    side = max(rows, cols) * protocol.cell_size
    scale = max(1.0, (side / 100.0) ** 2)
    return (f"{ground_truth.name} is {cols * protocol.cell_size:.0f} m x {rows * protocol.cell_size:.0f} m; "
            f"--max-steps {protocol.max_steps} suits the benchmark's 100 m mazes: raise it with the map's area "
            f"(e.g. --max-steps {int(math.ceil(protocol.max_steps * scale / 100.0) * 100)})")


@app.command("resample-map")
def resample_map_command(
    map_path: Path = typer.Option(..., "--map", help="Maze PNG, ROS map YAML or .npy grid."),
    out: Path = typer.Option(..., help="The ROS map YAML to write (its .pgm image beside it)."),
    to_cell_size: float = typer.Option(0.4, help="Metres per cell of the new map: a whole multiple of the map's own "
                                                 "(the benchmark's 0.4 m, which the shipped models were trained at)."),
    wall_cells: int = typer.Option(
        1, min=1, help="A new cell is an obstacle when it holds at least this many of the old map's obstacle cells "
                       "(1: any, so no wall is ever erased; more keeps walls thin but opens holes in thin oblique ones)."),
    speck_area: float = typer.Option(0.1, help="Obstacles of at most this many square metres (chair legs, scan noise) "
                                               "are erased first, so they do not become whole cells; 0 keeps every one."),
    start: Optional[tuple[float, float]] = typer.Option(
        None, help="Start, as in `explore`: COL ROW cell for a .npy grid or a maze PNG, X Y metres for a ROS map "
                   "(else its YAML 'start')."),
    cell_size: float = CellSize,
) -> None:
    """Write a coarser copy of a map as a ROS map (YAML + PGM) with its start: a 0.05 m SLAM map on the 0.4 m grid.

    A fine map explores badly under the protocol's 720-ray lidar (rays skip cells far out, clutter
    leaves frontier everywhere) and its cell counts mean less area than the models were fitted to.
    """
    from pipeline.world.resample import resample_map, write_ros_map
    from pipeline.world.maps import load_map, ros_map_origin_and_image

    if out.suffix.lower() not in (".yaml", ".yml"):
        _fail(f"--out {out}: name the ROS map YAML to write (ending in .yaml)")
    origin, reads = (0.0, 0.0), {map_path.resolve()}
    try:
        ground_truth = load_map(map_path, start=start, cell_size=cell_size)
        if map_path.suffix.lower() in (".yaml", ".yml"):
            origin, image = ros_map_origin_and_image(map_path)
            reads.add(image.resolve())
        coarse, moved = resample_map(ground_truth, to_cell_size, wall_cells, speck_area)
    except MapError as error:
        _fail(str(error))
    except ValueError as error:
        _fail(f"{map_path}: {error}")
    if {out.resolve(), out.with_suffix(".pgm").resolve()} & reads:
        _fail(f"--out {out} would overwrite the map being read; write the coarser copy elsewhere")
    out.parent.mkdir(parents=True, exist_ok=True)
    image = write_ros_map(coarse, out, origin)
    if moved > 0:
        _warn(f"the start's {to_cell_size:g} m cell is not free (a wall or speck covers part of it): "
              f"moved {moved:.2f} m to the nearest free cell")
    rows, cols = coarse.free.shape
    typer.echo(f"{map_path.name}: {ground_truth.free.shape[1]}x{ground_truth.free.shape[0]} cells of "
               f"{ground_truth.cell_size:g} m -> {cols}x{rows} cells of {to_cell_size:g} m, "
               f"{coarse.free_cell_count} free")
    typer.echo(f"wrote {out} and {image}")


def _given(ctx: Optional[typer.Context], name: str) -> bool:
    """Whether the user set option `name` on the command line (not its default)."""
    import click

    return ctx is not None and ctx.get_parameter_source(name) == click.core.ParameterSource.COMMANDLINE


def _final_belief(ground_truth, result, protocol):
    """The belief at the end of an episode, rebuilt by replaying its trajectory."""
    from pipeline.world.simulator import Episode

    episode = Episode(ground_truth, protocol)
    for waypoint in result.trajectory[1:]:
        episode.move(waypoint)
    return episode.belief.grid


def _with_checkpoint(specs: list[str], checkpoint: Optional[Path]) -> list[str]:
    """`specs` with checkpoint=PATH added to each diffusion planner's; ValueError when a checkpoint
    is given but no planner uses a policy, or a spec names its own checkpoint too."""
    from pipeline.evaluation.benchmark import parse_planner_spec
    from pipeline.planners import planner_class
    from pipeline.models.exports import require_file

    if checkpoint is None:
        return specs
    require_file(checkpoint, "a planner checkpoint")
    out, used = [], False
    for spec in specs:
        parsed = parse_planner_spec(spec)
        if not planner_class(parsed.name).needs_policy:
            out.append(spec)
            continue
        if "checkpoint" in parsed.options:
            raise ValueError(f"planner {parsed.label!r} names its own checkpoint; drop it or --checkpoint")
        used = True
        options = ",".join(f"{k}={v}" for k, v in {**parsed.options, "checkpoint": str(checkpoint)}.items())
        out.append(f"{parsed.label}={parsed.name}:{options}")
    if not used:
        raise ValueError(
            "--checkpoint is a diffusion policy for guide, guide_noregion or dare, and no planner given uses one "
            "(guide_tsp and mapex take an inpainter as label=name:checkpoint=PATH)"
        )
    return out


@app.command()
def benchmark(
    maps: Path = typer.Option(..., help="Folder of maps (maze PNGs, .npy grids, ROS YAMLs)."),
    planner: list[str] = typer.Option(
        ..., "--planner", help="Planner name or labelled variant label=name:key=value,...; repeat for several."),
    out: Path = typer.Option(Path("runs/bench"), help="Output folder (trajectories, metrics.csv, summary.md)."),
    workers: Optional[int] = typer.Option(None, min=1, help="Parallel processes [default: all cores]."),
    seed: int = typer.Option(0, min=0, help="Seed for randomised planners."),
    tracking_uri: Optional[str] = typer.Option(None, help="MLflow store [default: $MLFLOW_TRACKING_URI or sqlite:///mlflow.db]."),
    experiment: str = typer.Option("benchmark", help="MLflow experiment name."),
    mlflow_log: bool = typer.Option(True, "--mlflow/--no-mlflow", help="Log one MLflow run per planner."),
    checkpoint: Optional[Path] = typer.Option(
        None, help="Trained policy for the diffusion planners (guide, guide_noregion, dare) "
                   "[default: models/ under the current folder, else the shipped one]."),
    baseline: Optional[str] = typer.Option(
        None, help="Label to compare every planner with, map by map, in summary.md ('' for none) "
                   "[default: greedy_utility when it runs]."),
    start: Optional[tuple[float, float]] = typer.Option(
        None, help="One start for every map, as in `explore` (needed for .npy grids and ROS maps without 'start'): "
                   "COL ROW cells for maze PNGs and .npy grids, X Y metres for ROS maps, so keep each kind in its own folder."),
    cell_size: float = CellSize, node_resolution: float = NodeRes, sensor_range: float = SensorRange,
    utility_range: Optional[float] = UtilityRange, region_size: float = RegionSize,
    done_unknown_cells: int = DoneCells, max_steps: int = MaxSteps,
) -> None:
    """Run every map in a folder with each planner, in parallel, and summarise.

    Exits 1 when an episode did not complete (the files are written either way).
    """
    from pipeline.evaluation.benchmark import (DEFAULT_BASELINE, BenchmarkInterrupted, parse_planner_spec, protocol_for_map,
                                    run_benchmark)
    from pipeline.world.maps import list_maps, load_map
    from pipeline.common.mlflow_store import check_tracking_uri
    from pipeline.reporting.tracking import log_benchmark

    _check_out_dir(out)
    protocol = _protocol(cell_size, node_resolution, sensor_range, utility_range, region_size, done_unknown_cells, max_steps)
    try:
        if mlflow_log:
            check_tracking_uri(tracking_uri)  # now, not after every episode has run
        map_paths = list_maps(maps)
        if not map_paths:
            _fail(f"{maps}: no maps in this folder (maze .png, .npy or ROS .yaml)")
        loaded, completable = {}, set()  # map name -> (its file, the map); names of maps not already warned about
        for path in map_paths:
            ground_truth = load_map(path, start=start, cell_size=cell_size)
            loaded[ground_truth.name] = (path, ground_truth)
            _warn_fine_map(ground_truth, protocol)
            if not _warn_unreachable(ground_truth, protocol):
                completable.add(ground_truth.name)
        specs = _with_checkpoint(list(planner), checkpoint)
        labels = [parse_planner_spec(spec).label for spec in specs]
        if baseline is None:
            baseline = DEFAULT_BASELINE if DEFAULT_BASELINE in labels else ""
        elif baseline and baseline not in labels:
            _fail(f"--baseline {baseline!r} is not among the planners' labels: {', '.join(labels)}")
        frame = run_benchmark(map_paths, specs, protocol, out, workers=workers, seed=seed, baseline=baseline or None,
                              start=start)
    except BenchmarkInterrupted as stop:
        kept = f"; {out}/metrics.csv and summary.md hold them" if stop.done else ""
        typer.echo(f"interrupted after {stop.done} of {stop.total} episodes{kept}", err=True)
        raise typer.Exit(code=130)
    except MapError as error:
        _fail(str(error))
    except KeyError as error:
        _fail(str(error.args[0]))
    except (ValueError, FileNotFoundError) as error:  # a malformed "label=name:key=value" spec, unknown option, no model
        _fail(str(error))
    typer.echo((out / "summary.md").read_text(), nl=False)
    if mlflow_log:
        log_benchmark(frame, out, protocol, maps=str(maps), tracking_uri=tracking_uri, experiment=experiment)
    typer.echo(f"wrote {out}/metrics.csv, {out}/summary.md, {out}/run.json and {len(frame)} "
               f"trajector{'ies' if len(frame) != 1 else 'y'}")
    incomplete = int((~frame["complete"].astype(bool)).sum())
    if incomplete:
        for name in sorted(set(frame.loc[frame["steps"] >= protocol.max_steps, "map"])):
            path, ground_truth = loaded[name]
            _warn(_step_limit_hint(ground_truth, protocol_for_map(protocol, ground_truth, path)))
        # Why a map could not be completed is worth a scan per failed map, but not one per map before the run.
        for name in sorted(set(frame.loc[~frame["complete"].astype(bool), "map"]) & completable):
            path, ground_truth = loaded[name]
            _warn_unobservable(ground_truth, protocol_for_map(protocol, ground_truth, path))
        typer.echo(f"{incomplete} of {len(frame)} episodes did not complete (see summary.md)", err=True)
        raise typer.Exit(code=1)


@app.command()
def replay(
    map_path: Path = typer.Option(..., "--map", help="The map the trajectory was run on."),
    trajectory: Path = typer.Option(..., help="Trajectory CSV (header x,y; first row 0,0)."),
    start: Optional[tuple[float, float]] = typer.Option(None, help="Start for .npy / ROS maps, as in `explore`."),
    cell_size: float = CellSize, node_resolution: float = NodeRes, sensor_range: float = SensorRange,
    done_unknown_cells: int = DoneCells,
    oracle: bool = typer.Option(False, "--oracle", help="Replay under the ground-truth planner's rule (optimal)."),
) -> None:
    """Replay a trajectory file through a fresh simulator; prints its distance and completion as JSON.

    `steps` counts the waypoints after the start up to completion (metrics.csv's column);
    `complete_after_waypoint` is the 1-based row of the file at which the map became complete
    (the start row is 1). Rows after completion count for nothing.

    Exits 1 when the trajectory breaks the motion rule or does not complete the map.
    """
    from pipeline.evaluation.benchmark import protocol_for_map
    from pipeline.world.maps import load_map
    from pipeline.world.simulator import replay as replay_trajectory
    from pipeline.world.trajectories import read_trajectory_csv

    protocol = _protocol(cell_size, node_resolution, sensor_range, None, 20.0, done_unknown_cells, 10**9)
    try:
        ground_truth = load_map(map_path, start=start, cell_size=cell_size)
        points = read_trajectory_csv(trajectory)
        result = replay_trajectory(ground_truth, points, protocol_for_map(protocol, ground_truth, map_path), oracle=oracle)
    except (MapError, ValueError) as error:
        _fail(str(error))
    typer.echo(
        json.dumps(
            {
                "map": ground_truth.name,
                "complete": result.complete,
                "complete_after_waypoint": result.complete_after_waypoint,  # 1-based row, the start row is 1
                "steps": result.steps,  # waypoints after the start up to completion, as metrics.csv counts them
                "distance_m": round(result.distance_m, 3),
                "motion_violations": result.motion_violations,
                "explored_ratio": round(result.explored_ratio, 5),
                "failure": result.failure,
            }
        )
    )
    if start is None and (not result.complete or result.motion_violations):
        recorded = _recorded_start(trajectory)
        if recorded is not None:
            typer.echo(f"note: {recorded[0]} says the run started at --start {recorded[1][0]:g} {recorded[1][1]:g}; "
                       "replay it with the same --start", err=True)
    if not result.complete or result.motion_violations:
        raise typer.Exit(code=1)  # as `explore`: scripts can test the exit status


def _recorded_start(trajectory: Path) -> tuple[Path, list[float]] | None:
    """(run.json, its start override) of the run that wrote `trajectory`: explore writes run.json
    beside it, benchmark one folder up (OUT/label/map.csv); None when neither records a start."""
    for record_path in (trajectory.parent / "run.json", trajectory.parent.parent / "run.json"):
        try:
            start = json.loads(record_path.read_text()).get("start")
        except (OSError, ValueError, AttributeError):
            continue
        if isinstance(start, list) and len(start) == 2:
            return record_path, start
    return None


@app.command("eval-predictor")
def eval_predictor(
    maps: Path = typer.Option(..., help="Folder of maps to explore (nearest_frontier)."),
    out: Path = typer.Option(Path("runs/predictor"), help="Output folder (precision.csv, table1.md, fig3.png)."),
    checkpoint: Optional[Path] = typer.Option(
        None, help="Inpainter export [default: models/inpainter/inpainter.pt when the pipeline has trained one, else the shipped one]."),
    sweep: bool = typer.Option(False, "--sweep", help="Also at tau 0.5-0.9: precision_by_threshold.csv, threshold_sweep.png."),
    threshold: Optional[float] = typer.Option(
        None,
        help="tau: P(free) at or above which a node is predicted, as the planners' `threshold=` [default: theirs].",
    ),
    start: Optional[tuple[float, float]] = typer.Option(None, help="Start for .npy / ROS maps, as in `explore`."),
) -> None:
    """Structural-inference precision (paper Table I) at exploration steps 15/30/45/60."""
    from pipeline.evaluation.predictor_eval import inpainter_path
    from stages import eval_predictor as eval_stage

    if threshold is not None and not 0.0 <= threshold <= 1.0:  # NaN fails this too
        _fail(f"--threshold must be a probability in [0, 1], got {threshold:g}")
    _check_out_dir(out)
    try:
        used = inpainter_path(checkpoint)
        tau = {} if threshold is None else {"threshold": threshold}
        frame = eval_stage.cli_main(maps, out, str(checkpoint) if checkpoint else None, sweep=sweep, start=start, **tau)
    except (MapError, FileNotFoundError, ValueError) as error:
        _fail(str(error))
    typer.echo(f"inpainter: {used}")
    typer.echo(frame.to_string(index=False))
    names = ("precision.csv", "precision_detail.csv", "table1.md", "precision_by_threshold.csv", "threshold_sweep.png", "fig3.png")
    written = [out / name for name in names]
    typer.echo("wrote " + ", ".join(str(path) for path in written if path.is_file()))


@stage_app.command("generate-mazes")
def stage_generate_mazes(params: Path = typer.Option(Path("params.yaml"), help="Parameters file.")) -> None:
    """DVC stage: training and test mazes from params.yaml's `mazes` section."""
    from stages import generate_mazes

    _run_stage(generate_mazes.main, params)


@stage_app.command("fit-gate")
def stage_fit_gate(params: Path = typer.Option(Path("params.yaml"), help="Parameters file.")) -> None:
    """DVC stage: the sliver gate from greedy episodes in the training mazes (params.yaml's `fit_gate`)."""
    from stages import fit_gate

    _run_stage(fit_gate.main, params)


@stage_app.command("train-block-model")
def stage_train_block_model(params: Path = typer.Option(Path("params.yaml"), help="Parameters file.")) -> None:
    """DVC stage: the block model of `sampled_lookahead` from greedy episodes in the training mazes."""
    from stages import train_block_model

    _run_stage(train_block_model.main, params)


@stage_app.command("benchmark")
def stage_benchmark(params: Path = typer.Option(Path("params.yaml"), help="Parameters file.")) -> None:
    """DVC stage: the configured planners on the test mazes, reports in reports/benchmark/."""
    from stages import benchmark as benchmark_stage

    _run_stage(benchmark_stage.main, params)


@stage_app.command("collect-pairs")
def stage_collect_pairs(
    params: Path = typer.Option(Path("params.yaml"), help="Parameters file."),
    backend: Optional[str] = typer.Option(None, help="process (default) or ray (pip install '.[ray]')."),
) -> None:
    """DVC stage: Stage I node-image pairs from rollouts in the training mazes."""
    from stages import collect_pairs

    _check_backend(backend)
    _run_stage(collect_pairs.main, params, backend)


@stage_app.command("collect-expert")
def stage_collect_expert(
    params: Path = typer.Option(Path("params.yaml"), help="Parameters file."),
    backend: Optional[str] = typer.Option(None, help="process (default) or ray (pip install '.[ray]')."),
) -> None:
    """DVC stage: Stage II expert episodes on the training mazes."""
    from stages import collect_expert

    _check_backend(backend)
    _run_stage(collect_expert.main, params, backend)


@stage_app.command("train-inpainter")
def stage_train_inpainter(
    params: Path = typer.Option(Path("params.yaml"), help="Parameters file."),
    accelerator: Optional[str] = typer.Option(None, help="Lightning accelerator (cpu, gpu, auto) [default: params]."),
    devices: Optional[str] = typer.Option(None, help="Lightning devices (1, 2, auto) [default: params]."),
    resume: bool = typer.Option(False, "--resume", help="Continue from models/inpainter/last.ckpt."),
    init_checkpoint: Optional[Path] = typer.Option(
        None, help="Weights to start from: an official Big-LaMa checkpoint (.ckpt/.pth with generator.* weights) "
                   "or one of our inpainter.pt exports, e.g. pipeline/assets/inpainter.pt (fine-tuned in its own layout)."),
    tracking_uri: Optional[str] = typer.Option(None, help="MLflow store [default: $MLFLOW_TRACKING_URI or sqlite:///mlflow.db]."),
    progress: bool = typer.Option(False, "--progress", help="Show Lightning's progress bar."),
) -> None:
    """DVC stage: train the Stage I inpainter from params.yaml's `train_inpainter` section."""
    from stages import train_inpainter

    device_count = int(devices) if devices and devices.isdigit() else devices
    _run_stage(train_inpainter.main, params, accelerator, device_count, resume,
               str(init_checkpoint) if init_checkpoint else None, tracking_uri, progress)


@stage_app.command("build-observations")
def stage_build_observations(params: Path = typer.Option(Path("params.yaml"), help="Parameters file.")) -> None:
    """DVC stage: expert episodes replayed into graph observations with the frozen predictor."""
    from stages import build_observations

    _run_stage(build_observations.main, params)


def _train_planner(params: Path, variant: str, accelerator: Optional[str], devices: Optional[str], resume: bool,
                   max_epochs: Optional[int]) -> None:
    from stages import train_planner

    _run_stage(train_planner.main, params, variant, accelerator, devices, resume, max_epochs)


_Variant = typer.Option("guide", help="guide (global graph with predictions) or dare (observed graph only).")
_Accelerator = typer.Option(None, help="Lightning accelerator (cpu, gpu, auto) [default: params].")
_Devices = typer.Option(None, help="Lightning devices (1, 2, auto) [default: params].")
_Resume = typer.Option(False, "--resume", help="Continue from models/planner_<variant>/last.ckpt.")
_MaxEpochs = typer.Option(None, help="Override train_planner.train.max_epochs.")


@stage_app.command("train-planner")
def stage_train_planner(params: Path = typer.Option(Path("params.yaml"), help="Parameters file."), variant: str = _Variant,
                        accelerator: Optional[str] = _Accelerator, devices: Optional[str] = _Devices,
                        resume: bool = _Resume, max_epochs: Optional[int] = _MaxEpochs) -> None:
    """DVC stage: Stage II training of the diffusion planner from params.yaml's `train_planner` section."""
    _train_planner(params, variant, accelerator, devices, resume, max_epochs)


@app.command("train-planner")
def train_planner_command(params: Path = typer.Option(Path("params.yaml"), help="Parameters file."), variant: str = _Variant,
                          accelerator: Optional[str] = _Accelerator, devices: Optional[str] = _Devices,
                          resume: bool = _Resume, max_epochs: Optional[int] = _MaxEpochs) -> None:
    """Train the diffusion planner on data/observations/<variant>.npz (same as `guide stage train-planner`)."""
    _train_planner(params, variant, accelerator, devices, resume, max_epochs)


@stage_app.command("report")
def stage_report(params: Path = typer.Option(Path("params.yaml"), help="Parameters file.")) -> None:
    """DVC stage: Tables I-IV beside the paper's (runs the K sweep), reports/report.md and reports/tables/."""
    from stages import report as report_stage

    _run_stage(report_stage.main, params)


@stage_app.command("eval-predictor")
def stage_eval_predictor(params: Path = typer.Option(Path("params.yaml"), help="Parameters file.")) -> None:
    """DVC stage: Table I precision on the test mazes, reports in reports/predictor/."""
    from stages import eval_predictor as eval_stage

    _run_stage(eval_stage.main, params)


def main() -> None:  # pragma: no cover - console entry point
    app()


if __name__ == "__main__":  # pragma: no cover
    sys.exit(app())
