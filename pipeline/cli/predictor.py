"""`guide eval-predictor`: the node predictor's precision on a folder of maps (paper Table I)."""

from __future__ import annotations

from pathlib import Path
from typing import Optional

import typer

from pipeline.cli.options import check_out_dir, fail
from pipeline.models.defaults import inpainter_path
from pipeline.workflows.table1 import table1_for_folder
from pipeline.world.map_files import MapError

app = typer.Typer(rich_markup_mode=None)


@app.command("eval-predictor")
def eval_predictor(
    maps: Path = typer.Option(..., help="Folder of maps to explore (nearest_frontier)."),
    out: Path = typer.Option(Path("runs/predictor"), help="Output folder (precision.csv, table1.md, fig3.png)."),
    checkpoint: Optional[Path] = typer.Option(
        None,
        help="Inpainter export [default: models/inpainter/inpainter.pt when the pipeline has trained one, else the shipped one].",
    ),
    sweep: bool = typer.Option(
        False, "--sweep", help="Also at tau 0.5-0.9: precision_by_threshold.csv, threshold_sweep.png."
    ),
    threshold: Optional[float] = typer.Option(
        None,
        help="tau: P(free) at or above which a node is predicted, as the planners' `threshold=` [default: theirs].",
    ),
    start: Optional[tuple[float, float]] = typer.Option(None, help="Start for .npy / ROS maps, as in `explore`."),
) -> None:
    """Structural-inference precision (paper Table I) at exploration steps 15/30/45/60."""
    if threshold is not None and not 0.0 <= threshold <= 1.0:  # NaN fails this too
        fail(f"--threshold must be a probability in [0, 1], got {threshold:g}")
    check_out_dir(out)
    try:
        used = inpainter_path(checkpoint)
        tau = {} if threshold is None else {"threshold": threshold}
        frame = table1_for_folder(maps, out, str(checkpoint) if checkpoint else None, sweep=sweep, start=start, **tau)
    except (MapError, FileNotFoundError, ValueError) as error:
        fail(str(error))
    typer.echo(f"inpainter: {used}")
    typer.echo(frame.to_string(index=False))
    names = (
        "precision.csv",
        "precision_detail.csv",
        "table1.md",
        "precision_by_threshold.csv",
        "threshold_sweep.png",
        "fig3.png",
    )
    written = [out / name for name in names]
    typer.echo("wrote " + ", ".join(str(path) for path in written if path.is_file()))
