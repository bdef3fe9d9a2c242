"""What the commands share: the protocol's options, one-line errors and warnings, output folders."""

from __future__ import annotations

import re
import tempfile
from pathlib import Path
from typing import NoReturn, Optional

import typer

from pipeline.common.config import validate
from pipeline.world.protocol import Protocol


def fail(message: str) -> NoReturn:
    """One `error:` line on stderr, exit status 2."""
    typer.echo(f"error: {message}", err=True)
    raise typer.Exit(code=2)


def warn(message: str) -> None:
    typer.echo(f"warning: {message}", err=True)


def check_out_dir(out: Path) -> None:
    """Fail before any work when --out names something other than a folder, or one that cannot be
    made or written (a file on its path, a read-only disk); the folder exists afterwards."""
    if out.exists() and not out.is_dir():
        fail(f"{out}: exists and is not a folder; --out takes a folder (created if missing)")
    try:
        out.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=out).close()
    except OSError as error:
        fail(f"{out}: cannot create or write the output folder ({error.strerror or error})")


def check_bag_out(path: Path) -> None:
    """Fail before any work when an MCAP output cannot be written: not a .mcap name, a folder in the
    way, a folder that cannot be made, or the robot extra missing."""
    if path.suffix.lower() != ".mcap":
        fail(f"{path}: an MCAP recording's name ends in .mcap")
    if path.is_dir():
        fail(f"{path}: is a folder; give the MCAP file's name")
    try:
        import mcap  # noqa: F401
        import rosbags  # noqa: F401
    except ImportError:
        fail("recording MCAP needs rosbags and mcap: pip install '.[robot]'")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=path.parent).close()
    except OSError as error:
        fail(f"{path.parent}: cannot create or write the folder ({error.strerror or error})")


def given(ctx: Optional[typer.Context], name: str) -> bool:
    """Whether the user set option `name` on the command line (not its default). Compared by the
    source's name: newer typer releases carry their own copy of click, whose ParameterSource is
    not `click.core`'s."""
    source = ctx.get_parameter_source(name) if ctx is not None else None
    return source is not None and source.name == "COMMANDLINE"


def protocol(
    cell_size: float,
    node_resolution: float,
    sensor_range: float,
    utility_range: Optional[float],
    region_size: Optional[float],
    done_unknown_cells: int,
    max_steps: int,
    robot_radius_m: float = Protocol().robot_radius_m,
    door_graph: Optional[bool] = None,
) -> Protocol:
    """The protocol the options name; a refused value is an error naming its option."""
    values = dict(
        cell_size=cell_size,
        node_resolution=node_resolution,
        sensor_range=sensor_range,
        utility_range=utility_range if utility_range is not None else sensor_range / 2,
        region_size=region_size if region_size is not None else sensor_range,
        done_unknown_cells=done_unknown_cells,
        max_steps=max_steps,
        robot_radius_m=robot_radius_m,
        door_graph=door_graph,
    )
    try:
        return validate(Protocol, values, "protocol")
    except ValueError as error:  # named by the options: "protocol.sensor_range" -> "--sensor-range"
        fail(re.sub(r"protocol\.(\w+)", lambda m: "--" + m.group(1).replace("_m", "").replace("_", "-"), str(error)))


_DEFAULT = Protocol()
CellSize = typer.Option(
    _DEFAULT.cell_size, help="Metres per cell for maze PNGs and .npy grids (a ROS map has its own)."
)
NodeRes = typer.Option(_DEFAULT.node_resolution, help="Node lattice spacing d_n in metres.")
SensorRange = typer.Option(_DEFAULT.sensor_range, help="Lidar range in metres.")
UtilityRange = typer.Option(None, help="Frontier-utility range in metres [default: sensor range / 2].")
# Regions as wide as the sensor reaches: 20 m at the maze benchmark's 20 m sensor, 10 m at the real
# robot's 10 m (the best of 5, 10 and 20 m for guide_tsp on generated real-robot floors).
RegionSize = typer.Option(None, help="Side of the fixed regions in metres [default: the sensor range].")
DoneCells = typer.Option(
    _DEFAULT.done_unknown_cells, help="Done when ground-truth free minus belief free cells is at most this."
)
RobotRadius = typer.Option(
    _DEFAULT.robot_radius_m,
    "--robot-radius",
    help="The robot's radius in metres: what fits through a door (door-aware graph, done rule).",
)
DoorGraph = typer.Option(
    None,
    "--door-graph/--lattice-only",
    help="Door nodes off the lattice and 'done' checked on cells (docs/protocol.md, \"The whole "
    "building\") [default: on below a 2 m lattice, the building scale; DARE's lattice above].",
)
MaxSteps = typer.Option(_DEFAULT.max_steps, help="Waypoints before an episode ends as a failure.")
Start = typer.Option(
    None,
    help="Start: COL ROW cell for a .npy grid or a maze PNG (overrides its marked start), "
    "X Y metres for a ROS map (else its YAML 'start').",
)
Checkpoint = typer.Option(
    None,
    help="Trained policy for the diffusion planners (guide, guide_noregion, dare) "
    "[default: models/ under the current folder, else the shipped one].",
)
