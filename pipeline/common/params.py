"""Reading a stage's params file (`params.yaml` or a copy), with one clear error for a bad file.

Every stage reads its section through `load_params` / `params_section`, so a missing file,
a file that is not YAML (`--params README.md`), a file that is not a mapping of sections or
a missing section is a `ValueError` / `FileNotFoundError` naming the file; the stage runner
(`pipeline.stage_runner`) prints it as one `error:` line instead of a parser traceback.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import yaml

# A section's machine settings: how this machine runs a stage (its cores, engine, devices), never
# what the stage makes. dvc.yaml lists every other key of a section one by one and leaves these
# out, so that two machines with other core counts agree that the pipeline is up to date.
MACHINE_KEYS = ("workers", "threads", "accelerator", "devices", "device", "num_nodes")


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
        raise ValueError(
            f"{path}: a params file is a YAML mapping of sections (mazes:, benchmark:, ...), "
            f"not a {type(params).__name__}"
        )
    return params


def params_section(params: dict[str, Any], name: str, path: str | Path) -> dict[str, Any]:
    """The `name` section of a parsed params file, or a ValueError naming the file and section."""
    section = params.get(name)
    if section is None:
        raise ValueError(f"{path}: missing the '{name}' section")
    if not isinstance(section, dict):
        raise ValueError(f"{path}: the '{name}' section must be a mapping of settings, got {section!r}")
    return section
