"""`guide planners`: every registered planner with a one-line description."""

from __future__ import annotations

import typer

from pipeline.planners.registry import planner_class, planner_names

app = typer.Typer(rich_markup_mode=None)


@app.command()
def planners() -> None:
    """List every registered planner name with a one-line description."""
    for name in planner_names():
        cls = planner_class(name)
        oracle = " (oracle: sees the ground truth)" if cls.uses_ground_truth else ""
        typer.echo(f"{name:<18} {cls.description}{oracle}")
