"""Reading a stage's params file (`params.yaml` or a copy), with one clear error for a bad file.

Every stage reads its section through `load_params` / `params_section`, so a missing file,
a file that is not YAML (`--params README.md`), a file that is not a mapping of sections or
a missing section is a `ValueError` / `FileNotFoundError` naming the file; the stage runner
(`pipeline.stage_runner`) prints it as one `error:` line instead of a parser traceback.
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path
from typing import Any, Iterable, TypeVar

import yaml

T = TypeVar("T")


def yaml_problem(error: yaml.YAMLError) -> str:
    """What a YAML parser refused, with its line and column when it knows them (one line)."""
    problem = getattr(error, "problem", None)
    if not problem:
        lines = [line.strip() for line in str(error).splitlines() if line.strip()]
        problem = lines[-1] if lines else type(error).__name__
    mark = getattr(error, "problem_mark", None)
    where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark is not None else ""
    return f"{problem}{where}"


def load_params(path: str | Path) -> dict[str, Any]:
    """The parsed params file: a mapping of section name to settings ({} for an empty file)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: params file not found" if not path.exists() else f"{path}: not a file")
    try:
        params = yaml.safe_load(path.read_text(encoding="utf-8"))
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a params file (not UTF-8 text)") from None
    except yaml.YAMLError as error:
        raise ValueError(f"{path}: not valid YAML ({yaml_problem(error)})") from None
    if params is None:
        return {}
    if not isinstance(params, dict):
        raise ValueError(f"{path}: a params file is a YAML mapping of sections (mazes:, benchmark:, ...), "
                         f"not a {type(params).__name__}")
    return params


def params_section(params: dict[str, Any], name: str, path: str | Path) -> dict[str, Any]:
    """The `name` section of a parsed params file, or a ValueError naming the file and section."""
    section = params.get(name)
    if section is None:
        raise ValueError(f"{path}: missing the '{name}' section")
    if not isinstance(section, dict):
        raise ValueError(f"{path}: the '{name}' section must be a mapping of settings, got {section!r}")
    return section


def complete_section(params: dict[str, Any], name: str, path: str | Path, keys: Iterable[str]) -> dict[str, Any]:
    """The `name` section, which must name every one of `keys` and nothing else.

    A stage's settings live in the params file and nowhere else, so a missing key is an error
    naming it (not a default that could drift from the file's), and a key the stage does not
    know is refused by name as a likely typo (a silently ignored setting is worse than an error).
    """
    section = params_section(params, name, path)
    keys = sorted(keys)
    unknown = sorted(set(section) - set(keys))
    if unknown:
        raise ValueError(f"{path}: unknown {name} parameter(s) {unknown}; known: {keys}")
    missing = sorted(set(keys) - set(section))
    if missing:
        raise ValueError(f"{path}: the '{name}' section misses {missing} (params.yaml names every setting)")
    return dict(section)


def dataclass_from_dict(cls: type[T], values: dict[str, Any] | None, what: str) -> T:
    """`cls(**values)` where an unknown key is a ValueError naming it and the known ones.

    A params section or a saved model's config becomes its dataclass here, so that a typo
    (`max_epoch:`) is refused instead of silently falling back to a default.
    """
    values = dict(values or {})
    known = {f.name for f in fields(cls)}
    unknown = sorted(set(values) - known)
    if unknown:
        raise ValueError(f"unknown {what} {unknown}; known: {sorted(known)}")
    return cls(**values)
