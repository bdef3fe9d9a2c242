"""The `guide` command line: exploration, benchmarks, maps, recorded bags and the predictor's Table I.

Each command lives in a module of this package and is imported when it runs (`COMMANDS`), so
a command that needs no model (`guide mazes`, `guide replay`) never loads torch. The pipeline's
stages run as `dvc repro` (or `python -m stages.<name>`); `guide repro` is `dvc repro` that also
goes on after a run killed with its whole process group (`pipeline/cli/repro.py`).
"""

from __future__ import annotations

import importlib
import warnings

import typer
from typer import _click
from typer.core import TyperGroup

# command -> the module of this package that defines it (in a `typer.Typer` named `app`)
COMMANDS = {
    "planners": "pipeline.cli.planners",
    "mazes": "pipeline.cli.maps",
    "explore": "pipeline.cli.explore",
    "benchmark": "pipeline.cli.benchmark",
    "replay": "pipeline.cli.maps",
    "resample-map": "pipeline.cli.maps",
    "plans": "pipeline.cli.plans",
    "eval-predictor": "pipeline.cli.predictor",
    "bag": "pipeline.cli.bag",
    "repro": "pipeline.cli.repro",
}


class LazyCommands(TyperGroup):
    """A command group that imports a command's module only when that command is asked for."""

    def list_commands(self, ctx: _click.Context) -> list[str]:
        return list(COMMANDS)

    def get_command(self, ctx: _click.Context, cmd_name: str) -> _click.Command | None:
        if cmd_name not in COMMANDS:
            return None
        group = typer.main.get_group(importlib.import_module(COMMANDS[cmd_name]).app)
        return group.commands.get(cmd_name)


app = typer.Typer(
    cls=LazyCommands,
    help="GUIDE exploration: maps, simulator, planners, benchmarks and the predictor's Table I.",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,  # help texts hold literal brackets: [default: ...], '.[ray]'
)


def warning_line(message, category, filename, lineno, line=None) -> str:
    return f"warning: {message}\n"


@app.callback()
def _console(ctx: typer.Context) -> None:
    # A command line user gets a warning as one line, as errors are, not Python's file:line + source;
    # the usual format comes back when the command ends (the CLI may run inside another program).
    previous = warnings.formatwarning
    warnings.formatwarning = warning_line
    ctx.call_on_close(lambda: setattr(warnings, "formatwarning", previous))


def main() -> None:  # pragma: no cover - console entry point
    app()
