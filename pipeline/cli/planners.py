"""`guide planners`: every registered planner with a one-line description, or one planner's options."""

from __future__ import annotations

from typing import Optional

import typer

from pipeline.cli.options import fail
from pipeline.planners.registry import UnknownPlannerError, planner_config, planner_names

app = typer.Typer(rich_markup_mode=None)


@app.command()
def planners(
    options: Optional[str] = typer.Option(None, "--options", metavar="NAME",
                                          help="Print one planner's options: key, default and what it does."),
) -> None:
    """List every registered planner name with a one-line description (or, with --options NAME, its options).

    Options are set as label=name:key=value,... on the command line and in params.yaml, and as
    make_planner(name, key=value) in Python.
    """
    if options is not None:
        try:
            config = planner_config(options)
        except UnknownPlannerError as error:
            fail(str(error))
        typer.echo(f"{options}: {config.description}")
        if config.composition:
            typer.echo(f"  built as: {config.composition}")
        for info in config.options():
            if info.kinds is None:
                continue  # a Python object: not set from a spec
            typer.echo(f"  {info.name} = {_shown(info.default)}")
            typer.echo(f"      {info.help}")
        if config.objects and config.objects != ("base_options",):
            typer.echo(f"  (from Python only: {', '.join(o for o in config.objects if o != 'base_options')})")
        if getattr(config, "base_planner", None) is not None:
            typer.echo("  ...and the options of its base planner (guide planners --options BASE)")
        return
    for name in planner_names():
        config = planner_config(name)
        oracle = " (oracle: sees the ground truth)" if config.uses_ground_truth else ""
        typer.echo(f"{name:<18} {config.description}{oracle}")


def _shown(value) -> str:
    if value is None:
        return "None"
    if isinstance(value, bool):
        return str(value).lower()
    return str(value)
