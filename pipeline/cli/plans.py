"""`guide plans import`: real floor plans or a robot's saved SLAM maps as a map family (pipeline/world/plans.py)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer
from tqdm import tqdm

from pipeline.cli.options import fail
from pipeline.world.map_files import MapError
from pipeline.world.plans import MANIFEST, find_plan_sources, import_plans
from pipeline.world.protocol import PAPER_REAL_ROBOT

app = typer.Typer(rich_markup_mode=None)
plans_app = typer.Typer(
    rich_markup_mode=None, no_args_is_help=True, help="Floor plans and saved SLAM maps as a map family."
)
app.add_typer(plans_app, name="plans")


@plans_app.command("import")
def import_command(
    src: Path = typer.Argument(
        ...,
        help="A floor plan or saved map (ROS map .yaml, .png/.pgm, .npy), a MapEx-style "
        "folder (occ_map.npy, valid_space.npy), or a folder of them.",
    ),
    out: Path = typer.Option(
        ...,
        help="The folder to write the plans (ROS maps) and manifest.json into; replaced "
        "as a whole once every plan is written.",
    ),
    cell_size: float = typer.Option(
        PAPER_REAL_ROBOT.cell_size,
        help="Metres per cell of the written plans: a whole multiple of each source's resolution.",
    ),
    resolution: Optional[float] = typer.Option(
        None, help="Metres per pixel of .png/.pgm/.npy plans and MapEx folders (a ROS map YAML says its own)."
    ),
    robot_radius: float = typer.Option(
        PAPER_REAL_ROBOT.robot_radius_m,
        "--robot-radius",
        help="Metres: a gap this robot fits through stays open at the coarser cells.",
    ),
    starts: int = typer.Option(3, min=1, help="Start cells drawn per plan, apart from each other and clear of walls."),
    seed: int = typer.Option(0, min=0, help="The draw of the starts."),
    licence: Optional[str] = typer.Option(
        None,
        help="The licence line of every plan in the manifest [default: the "
        "first line of a LICENSE file beside the sources].",
    ),
) -> None:
    """Bring floor plans or saved SLAM maps to the protocol's cells as a map family `guide benchmark --maps` reads.

    Conservative (a cell is free only where all its finer cells are) except where the robot may
    stand, so no door it fits through closes; the largest free component kept; duplicates (equal up
    to the 8 rotations and flips) dropped; starts drawn clear of walls; the sources' licence files
    copied beside the plans. `guide plans import data/real_plans/kth --resolution 0.05 --out data/plans`.
    """
    if out.exists() and not out.is_dir():
        fail(f"{out}: exists and is not a folder; --out takes a folder")
    if out.is_dir() and any(out.iterdir()) and not (out / MANIFEST).is_file():
        fail(f"{out}: a folder that holds other files; --out replaces it as a whole, so name an empty or new one")
    if robot_radius < 0:
        fail(f"--robot-radius must be at least 0 m, got {robot_radius:g}")
    try:
        sources = find_plan_sources(src, resolution, licence)
        report = import_plans(
            sources,
            out,
            cell_size,
            robot_radius,
            starts,
            seed,
            progress=lambda items: tqdm(items, desc="plans", unit="plan"),
        )
    except MapError as error:
        fail(str(error))
    except (ValueError, OSError) as error:
        fail(f"{src}: {error}")
    for dropped, equals in report.duplicates:
        typer.echo(f"dropped {dropped}: the same plan as {equals} (up to rotation and flip)")
    area = sum(plan.free_m2 for plan in report.plans)
    typer.echo(
        f"wrote {len(report.plans)} plan{'s' if len(report.plans) != 1 else ''} ({area:,.0f} m^2 free) at "
        f"{cell_size:g} m to {out}, with {MANIFEST}" + (f" and {', '.join(report.licences)}" if report.licences else "")
    )
