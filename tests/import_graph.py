"""The project's own import graph, read from the source (nothing is imported): what the layer and
DVC-dependency tests check the code against."""

from __future__ import annotations

import ast
from functools import lru_cache
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("pipeline", "stages")


def module_path(module: str) -> Path | None:
    """The file of a project module (a package's __init__.py), or None for another project's."""
    if module.split(".")[0] not in PACKAGES:
        return None
    base = ROOT.joinpath(*module.split("."))
    for path in (base.with_suffix(".py"), base / "__init__.py"):
        if path.is_file():
            return path
    return None


@lru_cache(maxsize=None)
def imports_of(module: str) -> frozenset[str]:
    """Project modules that `module` imports anywhere in its file (parents included: importing
    a.b.c runs a/__init__.py and a/b/__init__.py)."""
    path = module_path(module)
    if path is None:
        return frozenset()
    found: set[str] = set()
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        names: list[str] = []
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            base = node.module or ""
            if node.level:
                parts = package.split(".")
                base = ".".join(parts[: len(parts) - node.level + 1] + ([base] if base else []))
            names = [base] + [f"{base}.{alias.name}" for alias in node.names]
        for name in names:
            parts = name.split(".")
            for end in range(1, len(parts) + 1):
                candidate = ".".join(parts[:end])
                if module_path(candidate) is not None and candidate != module:
                    found.add(candidate)
    return frozenset(found)


def closure(module: str) -> set[str]:
    """`module` and every project module it reaches through imports."""
    seen, todo = {module}, [module]
    while todo:
        for name in imports_of(todo.pop()):
            if name not in seen:
                seen.add(name)
                todo.append(name)
    return seen


def all_modules() -> list[str]:
    """Every module of the project's packages."""
    modules = []
    for package in PACKAGES:
        for path in sorted((ROOT / package).rglob("*.py")):
            parts = path.relative_to(ROOT).with_suffix("").parts
            modules.append(".".join(parts[:-1] if parts[-1] == "__init__" else parts))
    return modules


def code_unit(module: str) -> str:
    """What a DVC stage names for a module: the folder of its `pipeline` sub-package, or its file
    when it sits at the top of `pipeline` or in `stages`."""
    parts = module.split(".")
    path = module_path(module)
    assert path is not None
    if parts[0] == "pipeline" and len(parts) >= 2 and (ROOT / "pipeline" / parts[1]).is_dir():
        return f"pipeline/{parts[1]}"
    return path.relative_to(ROOT).as_posix()
