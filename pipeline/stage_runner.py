"""How every stage runs: `python -m stages.<name> [--params FILE]`, with one `error:` line instead
of a traceback when it fails for a reason the user can fix.

`dvc repro` runs each stage so. A missing input, a bad setting or a stage's own refusal is
reported the same way by every stage: `error: <message>` on stderr, exit status 2. Anything
else (a bug) keeps its traceback.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any, Callable, TypeVar

from pipeline.common.config import Section, validate
from pipeline.common.params import load_params, params_section
from pipeline.world.map_files import MapError
from pipeline.world.protocol import Protocol

S = TypeVar("S", bound=Section)
UPSTREAM_HINT = " (run the upstream stages first: `dvc repro`)"


def user_error_message(error: BaseException) -> str | None:
    """The one-line message for an error the user can fix, or None for one that is a bug."""
    if isinstance(error, (MapError, FileNotFoundError)):
        upstream = any(part in str(error) for part in ("data/", "models/")) and "stage" not in str(error)
        return f"{error}" + (UPSTREAM_HINT if upstream else "")
    if isinstance(error, ValueError):  # an unknown planner name too (`UnknownPlannerError`)
        return str(error)
    if isinstance(error, SystemExit) and isinstance(error.code, str):  # a stage's own sys.exit("error: ...")
        return error.code.removeprefix("error: ")
    return None


def run_stage_main(main: Callable[..., Any], *args: Any) -> Any:
    """`main(*args)`, with user errors printed as one `error:` line and exit status 2."""
    try:
        return main(*args)
    except (Exception, SystemExit) as error:
        message = user_error_message(error)
        if message is None:
            raise
        print(f"error: {message}", file=sys.stderr)
        raise SystemExit(2) from None


def read_stage(params_path: str | Path, section: str, settings: type[S]) -> S:
    """A stage's section of the params file as its `Settings` model, checked before the stage
    reads, writes or deletes anything; a ValueError `<file>: <section.key>: must be ..., got ...`
    for the first value refused. A missing file or bad YAML is `load_params`'s one-line error."""
    values = params_section(load_params(params_path), section, params_path)
    try:
        return validate(settings, values, section)
    except ValueError as error:
        raise ValueError(f"{params_path}: {error}") from None


def read_protocol(params_path: str | Path) -> Protocol:
    """The params file's shared `protocol` section (it may be left out: the maze benchmark's values)."""
    values = load_params(params_path).get("protocol")
    try:
        return Protocol.from_dict(values)
    except ValueError as error:
        raise ValueError(f"{params_path}: {error}") from None


def stage_arguments(doc: str | None) -> argparse.ArgumentParser:
    """A stage's command-line parser: its docstring's first line as help, and --params."""
    parser = argparse.ArgumentParser(description=(doc or "").strip().splitlines()[0] if doc else None)
    parser.add_argument("--params", default="params.yaml", help="parameters file [default: params.yaml]")
    return parser
