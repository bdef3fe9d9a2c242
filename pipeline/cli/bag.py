"""`guide bag`: a planner on a recorded ROS 2 bag, a plan at every map, written to MCAP for Foxglove."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from pipeline.cli.options import Checkpoint, check_bag_out, fail, warn
from pipeline.evaluation.benchmark import with_policy_checkpoint
from pipeline.planners.matched_models import model_files
from pipeline.planners.specs import as_specs, build_planner, resolve_planner_specs
from pipeline.robot.bag_replay import replay_bag
from pipeline.robot.session import ExplorationSession
from pipeline.world.protocol import PROTOCOLS

app = typer.Typer(rich_markup_mode=None)


@app.command()
def bag(
    bag_path: Path = typer.Option(
        ...,
        "--bag",
        help="ROS 2 bag: a rosbag2 folder (sqlite3 or MCAP) or a .mcap file, "
        "with the map topic and /tf (map -> base_link).",
    ),
    out: Path = typer.Option(
        ...,
        "--out",
        help="Output MCAP: the input maps, the poses, and each decision's plan "
        "(/guide/plan), next waypoint, graph markers and record.",
    ),
    planner: str = typer.Option("guide", help="Planner name (see `guide planners`) or label=name:key=value,..."),
    map_topic: str = typer.Option("/map", "--map-topic", help="The nav_msgs/OccupancyGrid topic."),
    base_frame: str = typer.Option("base_link", "--base-frame", help="The robot's tf frame."),
    protocol: str = typer.Option(
        "real_robot",
        help=f"The planner's protocol: {' or '.join(PROTOCOLS)} "
        "(lattice spacing, lidar range, cell size the map is brought to).",
    ),
    seed: int = typer.Option(0, min=0, help="Seed for randomised planners."),
    checkpoint: Optional[Path] = Checkpoint,
    progress: bool = typer.Option(True, "--progress/--no-progress", help="Show a progress bar on stderr."),
    save_map: Optional[Path] = typer.Option(
        None,
        "--save-map",
        help="A folder to write the final belief into as a "
        "ROS map (map.yaml + map.pgm), which `guide plans "
        "import` takes as training data.",
    ),
) -> None:
    """Run a planner along a recorded bag: at every map the session decides afresh from the robot's
    recorded pose; the plans, graphs and records go to an MCAP next to the input."""
    if not bag_path.exists():
        fail(f"{bag_path}: no such bag")
    if protocol not in PROTOCOLS:
        fail(f"--protocol: must be one of {', '.join(PROTOCOLS)}, got {protocol!r}")
    check_bag_out(out)
    if out.resolve() == bag_path.resolve():
        fail(f"{out}: is the input bag; give another name")
    try:
        (spec,) = resolve_planner_specs(with_policy_checkpoint(as_specs([planner]), checkpoint))
        agent = build_planner(spec)
        session = ExplorationSession(agent, PROTOCOLS[protocol], seed=seed)
    except (ValueError, FileNotFoundError, TypeError) as error:
        fail(str(error))
    typer.echo(f"{spec.label}: {agent.description}")
    files = model_files(agent)
    if files:
        typer.echo(f"models: {', '.join(files)}")
    try:
        result = replay_bag(bag_path, out, session, map_topic=map_topic, base_frame=base_frame, progress=progress)
    except (ValueError, FileNotFoundError) as error:
        fail(str(error))
    except Exception as error:  # rosbags' reader errors: a file that is not a bag
        if type(error).__module__.startswith("rosbags"):
            fail(f"{bag_path}: cannot read the bag ({error})")
        raise
    typer.echo(result.summary())
    if save_map is not None:
        if session.canvas is None:
            warn(f"--save-map: no map to save (the bag gave no usable map on {map_topic})")
        else:
            typer.echo(f"wrote {session.save_map(save_map)}")
    if result.maps and not result.plans:
        warn(
            f"no plan: the bag's tf never placed {base_frame} in the map's frame; choose the robot's frame with "
            "--base-frame"
            if result.waiting == result.maps
            else f"no plan ({result.last_skip})"
        )
        raise typer.Exit(code=1)
