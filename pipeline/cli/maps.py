"""`guide mazes`, `guide resample-map`, `guide replay`: maps and trajectories, no model needed."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path
from typing import Any, Callable, Optional, Sequence, cast

import typer

from pipeline.cli.options import (
    CellSize,
    DoneCells,
    DoorGraph,
    NodeRes,
    RobotRadius,
    SensorRange,
    check_out_dir,
    fail,
    protocol,
    warn,
)
from pipeline.world.building_config import BuildingConfig
from pipeline.world.buildings import generate_building_set
from pipeline.world.caves import CaveConfig, generate_cave_set
from pipeline.world.map_files import MapError
from pipeline.world.maps import load_map, ros_map_origin_and_image
from pipeline.world.mazes import MIN_BLOCK_PIXELS, MazeConfig, generate_maze_set
from pipeline.world.offices import OFFICE_SCALES, OfficeConfig, generate_office_set
from pipeline.world.protocol import Protocol, protocol_for_map
from pipeline.world.resample import resample_map, write_ros_map
from pipeline.world.simulator import MotionError
from pipeline.world.simulator import replay as replay_trajectory
from pipeline.world.team_files import TEAM_SUFFIX, read_team_csv
from pipeline.world.team_replay import replay_team
from pipeline.world.trajectories import read_trajectory_csv, recorded_start, write_steps_csv

app = typer.Typer(rich_markup_mode=None)


@app.command()
def mazes(
    out: Path = typer.Option(
        ..., help="Folder to write maze_NNNN.png (office_, building_, cave_NNNN.png) into (created if missing)."
    ),
    count: int = typer.Option(..., min=1, help="How many mazes."),
    seed: int = typer.Option(0, min=0, help="Maze i is drawn from seed sequence [seed, i]."),
    side: float = typer.Option(100.0, help="Side length in metres (for mazes, a multiple of the block size)."),
    kind: str = typer.Option(
        "maze",
        help="maze: like the benchmark's; office: office floors (thin walls, "
        "wide rooms, clutter), a family the sliver gate is also fitted on; "
        "building: floors drawn like real plans at the real-robot scale (wings, L, U and "
        "courtyard shapes, corridors with rooms on both sides, rooms of one door, "
        "walls at any phase of the 1 m lattice, furniture; --cell-size 0.2); cave: rough-walled caves, a family no model is fitted on.",
    ),
    scale: str = typer.Option(
        "maze",
        help="Office floor sizes: maze (doors wider than the 4 m lattice) or "
        "real_robot (building sizes for 0.2 m cells and a 1 m lattice: "
        "doors from 0.8 m, walls 0.1-0.3 m, rooms from 3 m).",
    ),
    cell_size: float = CellSize,
) -> None:
    """Draw mazes like the benchmark's (the pipeline's generator and defaults), office floors or caves, into a folder.

    More maps than the 12 test mazes make a benchmark comparison resolve smaller differences:
    `guide mazes --out runs/mazes --count 50 --seed 7 && guide benchmark --maps runs/mazes ...`.
    """
    if kind not in ("maze", "office", "building", "cave"):
        fail(f"--kind must be maze, office, building or cave, got {kind!r}")
    if scale not in OFFICE_SCALES:
        fail(f"--scale must be {' or '.join(OFFICE_SCALES)}, got {scale!r}")
    if scale != "maze" and kind != "office":
        fail(f"--scale {scale} sizes office floors; drop it or add --kind office")
    if not (math.isfinite(side) and side > 0):
        fail(f"--side must be a positive number of metres, got {side:g}")
    if kind != "maze":
        config_class, write_set, what = cast(
            "dict[str, tuple[Any, Callable[..., list[Path]], str]]",  # (config, its generate_*_set, words)
            {
                "office": (OfficeConfig, generate_office_set, "office floor"),
                "building": (BuildingConfig, generate_building_set, "building floor"),
                "cave": (CaveConfig, generate_cave_set, "cave"),
            },
        )[kind]
        try:
            family = (
                OfficeConfig.for_scale(scale, side, cell_size)
                if kind == "office"
                else config_class(side_m=side, cell_size=cell_size)
            )
        except ValueError as error:  # named by this command's words, not the config's fields
            message = str(error).replace(f"{config_class.__name__} needs", f"{what}s need")
            message = message.replace("BuildingConfig.lattice_m (1 m)", "the 1 m lattice of building floors")
            fail(message.replace("CaveConfig.block_m", "the 4 m block").replace("cells (", "cells of --cell-size ("))
        check_out_dir(out)
        if out.is_dir() and any(out.glob(f"{kind}_*.png")):
            fail(f"{out} already holds {kind} PNGs: pick an empty folder, so no old {what} mixes into a set")
        paths = write_set(family, count, out, seed=seed)
        typer.echo(f"wrote {len(paths)} {what}{'s' if len(paths) != 1 else ''} of {side:g} m to {out}")
        return
    try:
        config = MazeConfig(side_m=(side, side), cell_size=cell_size)
    except ValueError as error:  # named by this command's options, not the config's fields
        if "MazeConfig.block_m" in str(error):
            fail(
                f"--cell-size {cell_size:g} does not fit the mazes' {MazeConfig.block_m:g} m blocks: a block must be "
                f"a whole number (at least {MIN_BLOCK_PIXELS}) of half-cells ({cell_size / 2:g} m); 0.2, 0.4 or 0.5 m fit"
            )
        message = re.sub(r"MazeConfig\.side_m \([^)]*\)", f"--side {side:g}", str(error))
        fail(message.replace("MazeConfig.side_m", "--side").replace("MazeConfig.cell_size", "--cell-size"))
    check_out_dir(out)  # after the settings: a refused one leaves no folder behind
    stale = sorted(out.glob("maze_*.png")) if out.is_dir() else []
    if stale:
        fail(f"{out} already holds {len(stale)} maze PNGs: pick an empty folder, so no old maze mixes into a set")
    paths = generate_maze_set(config, count, out, seed=seed)
    typer.echo(f"wrote {len(paths)} maze{'s' if len(paths) != 1 else ''} of {config.side_m[0]:g} m to {out}")


@app.command("resample-map")
def resample_map_command(
    map_path: Path = typer.Option(..., "--map", help="Maze PNG, ROS map YAML or .npy grid."),
    out: Path = typer.Option(..., help="The ROS map YAML to write (its .pgm image beside it)."),
    to_cell_size: float = typer.Option(
        0.4,
        help="Metres per cell of the new map: a whole multiple of the map's own "
        "(the benchmark's 0.4 m, which the shipped models were trained at).",
    ),
    wall_cells: int = typer.Option(
        1,
        min=1,
        help="A new cell is an obstacle when it holds at least this many of the old map's obstacle cells "
        "(1: any, so no wall is ever erased; more keeps walls thin but opens holes in thin oblique ones).",
    ),
    speck_area: float = typer.Option(
        0.1,
        help="Obstacles of at most this many square metres (chair legs, scan noise) "
        "are erased first, so they do not become whole cells; 0 keeps every one.",
    ),
    start: Optional[tuple[float, float]] = typer.Option(
        None,
        help="Start, as in `explore`: COL ROW cell for a .npy grid or a maze PNG, X Y metres for a ROS map "
        "(else its YAML 'start').",
    ),
    cell_size: float = CellSize,
) -> None:
    """Write a coarser copy of a map as a ROS map (YAML + PGM) with its start: a 0.05 m SLAM map on the 0.4 m grid.

    A fine map explores badly under the protocol's 720-ray lidar (rays skip cells far out, clutter
    leaves frontier everywhere) and its cell counts mean less area than the models were fitted to.
    """
    if out.suffix.lower() not in (".yaml", ".yml"):
        fail(f"--out {out}: name the ROS map YAML to write (ending in .yaml)")
    origin, reads = (0.0, 0.0), {map_path.resolve()}
    try:
        ground_truth = load_map(map_path, start=start, cell_size=cell_size)
        if map_path.suffix.lower() in (".yaml", ".yml"):
            origin, image = ros_map_origin_and_image(map_path)
            reads.add(image.resolve())
        coarse, moved = resample_map(ground_truth, to_cell_size, wall_cells, speck_area)
    except MapError as error:
        fail(str(error))
    except ValueError as error:
        fail(f"{map_path}: {error}")
    if {out.resolve(), out.with_suffix(".pgm").resolve()} & reads:
        fail(f"--out {out} would overwrite the map being read; write the coarser copy elsewhere")
    out.parent.mkdir(parents=True, exist_ok=True)
    image = write_ros_map(coarse, out, origin)
    if moved > 0:
        warn(
            f"the start's {to_cell_size:g} m cell is not free (a wall or speck covers part of it): "
            f"moved {moved:.2f} m to the nearest free cell"
        )
    rows, cols = coarse.free.shape
    typer.echo(
        f"{map_path.name}: {ground_truth.free.shape[1]}x{ground_truth.free.shape[0]} cells of "
        f"{ground_truth.cell_size:g} m -> {cols}x{rows} cells of {to_cell_size:g} m, "
        f"{coarse.free_cell_count} free"
    )
    typer.echo(f"wrote {out} and {image}")


@app.command()
def replay(
    map_path: Path = typer.Option(..., "--map", help="The map the trajectory was run on."),
    trajectory: Path = typer.Option(
        ...,
        help="Trajectory CSV (header x,y; first row 0,0), or a team trajectory "
        "<map>.team.csv of `benchmark --robots` (header time_s,robot,x,y).",
    ),
    start: Optional[tuple[float, float]] = typer.Option(None, help="Start for .npy / ROS maps, as in `explore`."),
    cell_size: float = CellSize,
    node_resolution: float = NodeRes,
    sensor_range: float = SensorRange,
    done_unknown_cells: int = DoneCells,
    robot_radius: float = RobotRadius,
    door_graph: Optional[bool] = DoorGraph,
    oracle: bool = typer.Option(False, "--oracle", help="Replay under the ground-truth planner's rule (optimal)."),
    steps_csv: Optional[Path] = typer.Option(
        None,
        help="Also write the per-step record (step, distance, explored "
        "area and share) recomputed from the trajectory alone, as "
        "benchmark's OUT/<label>/<map>.steps.csv without decision times.",
    ),
) -> None:
    """Replay a trajectory file through a fresh simulator; prints its distance and completion as JSON.

    `steps` counts the waypoints after the start up to completion (metrics.csv's column);
    `complete_after_waypoint` is the 1-based row of the file at which the map became complete
    (the start row is 1). Rows after completion count for nothing.

    A team file (<map>.team.csv) is replayed with every row's segment checked against the belief
    of all earlier rows; it prints the team's completion, makespan (seconds, as the file counts
    time) and each robot's distance.

    Exits 1 when the trajectory breaks the motion rule or does not complete the map.
    """
    rules = protocol(
        cell_size, node_resolution, sensor_range, None, 20.0, done_unknown_cells, 10**9, robot_radius, door_graph
    )
    if trajectory.name.endswith(TEAM_SUFFIX):
        if steps_csv is not None:
            fail("--steps-csv is a single robot's per-step record; a team file has none")
        replay_team_file(map_path, trajectory, rules, start, cell_size, oracle)
        return
    try:
        ground_truth = load_map(map_path, start=start, cell_size=cell_size)
        points = read_trajectory_csv(trajectory)
        result = replay_trajectory(
            ground_truth,
            cast(Sequence[Sequence[float]], points),
            protocol_for_map(rules, ground_truth, map_path),
            oracle=oracle,
        )
    except (MapError, ValueError) as error:
        fail(str(error))
    if steps_csv is not None:
        if steps_csv.resolve() == trajectory.resolve():
            fail(f"--steps-csv {steps_csv} would overwrite the trajectory being replayed; write it elsewhere")
        write_steps_csv(steps_csv, result.step_rows())
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
        recorded = recorded_start(trajectory)
        if recorded is not None:
            typer.echo(
                f"note: {recorded[0]} says the run started at --start {recorded[1][0]:g} {recorded[1][1]:g}; "
                "replay it with the same --start",
                err=True,
            )
    if not result.complete or result.motion_violations:
        raise typer.Exit(code=1)  # as `explore`: scripts can test the exit status


def replay_team_file(
    map_path: Path,
    trajectory: Path,
    rules: Protocol,
    start: Optional[tuple[float, float]],
    cell_size: float,
    oracle: bool,
) -> None:
    """`guide replay` of a team file: its figures as JSON; exit 1 when it breaks the rule or does not complete."""
    try:
        ground_truth = load_map(map_path, start=start, cell_size=cell_size)
        rows = read_team_csv(trajectory)
        result = replay_team(ground_truth, rows, protocol_for_map(rules, ground_truth, map_path), oracle=oracle)
    except (MapError, ValueError) as error:
        fail(str(error))
    except MotionError as error:  # a start row off the lattice or outside the map
        fail(f"{trajectory}: {error}")
    typer.echo(
        json.dumps(
            {
                "map": ground_truth.name,
                "complete": result.complete,
                "robots": result.robots,
                "makespan_s": round(result.makespan_s, 3),  # the time of the row that completed the map
                "robot_distance_m": [round(d, 3) for d in result.robot_distance_m],
                "total_distance_m": round(result.total_distance_m, 3),
                "motion_violations": result.motion_violations,
                "explored_ratio": round(result.explored_ratio, 5),
                "failure": result.failure,
            }
        )
    )
    if not result.complete or result.motion_violations:
        raise typer.Exit(code=1)
