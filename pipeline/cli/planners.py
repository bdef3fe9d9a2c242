"""`guide planners`: every registered planner with a one-line description, or one planner's options."""

from __future__ import annotations

from typing import Optional

import typer

from pipeline.cli.options import fail
from pipeline.planners.protocol_defaults import PROTOCOL_OPTIONS, protocol_options
from pipeline.planners.registry import UnknownPlannerError, planner_config, planner_names

app = typer.Typer(rich_markup_mode=None)


@app.command()
def planners(
    options: Optional[str] = typer.Option(
        None, "--options", metavar="NAME", help="Print one planner's options: key, default and what it does."
    ),
    protocol: Optional[str] = typer.Option(
        None,
        "--protocol",
        metavar="NAME",
        help=f"With --options: the defaults at this protocol "
        f"({', '.join(PROTOCOL_OPTIONS)}); without it, the config's, "
        "each protocol's own noted beside them.",
    ),
) -> None:
    """List every registered planner name with a one-line description (or, with --options NAME, its options,
    by the part of the planner each sets: the paper's parts first, then ours).

    Options are set as label=name:key=value,... on the command line and in params.yaml, and as
    make_planner(name, key=value) in Python. Some defaults depend on the protocol a planner runs
    at (the maze benchmark's or the real robot's): --protocol NAME prints that protocol's table.
    """
    if protocol is not None and options is None:
        fail("--protocol goes with --options NAME: guide planners --options guide --protocol maze")
    if options is not None:
        try:
            config = planner_config(options)
            at_protocol = protocol_options(options, protocol) if protocol is not None else {}
        except (UnknownPlannerError, ValueError) as error:
            fail(str(error))
        others = {name: protocol_options(options, name) for name in PROTOCOL_OPTIONS}
        typer.echo(f"{options}: {config.description}")
        if config.composition:
            typer.echo(f"  built as: {config.composition}")
        if protocol is not None:
            typer.echo(
                f"  defaults at protocol {protocol}"
                + (
                    f" ({len(at_protocol)} differ from the config's, marked *)"
                    if at_protocol
                    else " (the config's own)"
                )
            )
        parts = [
            (title, [info for info in infos if info.kinds is not None])  # a Python object is not set from a spec
            for title, infos in config.option_parts()
        ]
        parts = [(title, infos) for title, infos in parts if infos]
        for title, infos in parts:
            if len(parts) > 1:
                typer.echo("  # " + (title or f"{options}'s own"))
            for info in infos:
                if protocol is not None:
                    mark = " *" if info.name in at_protocol else ""
                    typer.echo(f"  {info.name} = {_shown(at_protocol.get(info.name, info.default))}{mark}")
                else:
                    beside = [f"{n}: {_shown(table[info.name])}" for n, table in others.items() if info.name in table]
                    typer.echo(
                        f"  {info.name} = {_shown(info.default)}" + (f"   ({'; '.join(beside)})" if beside else "")
                    )
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
