"""The library's layers import one way, and a command that needs no model never loads torch."""

from __future__ import annotations

import ast
import os
import subprocess
import sys

import tomllib
import yaml
from import_graph import ROOT, all_modules, module_path


def test_the_layers_contract_is_kept():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    (contract,) = [c for c in config["contracts"] if c["type"] == "layers" and "containers" not in c]
    layers = {name.strip() for layer in contract["layers"] for name in layer.split("|")}
    assert len({name for name in layers if name.startswith("pipeline.")}) >= 6
    done = subprocess.run(
        ["lint-imports", "--config", str(ROOT / "pyproject.toml")],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stdout[-3000:]


def test_inside_planners_registration_sits_above_both_wings():
    """The paper's planner (guide/) and the baselines never import our additions (extensions/) or the
    registration that composes them (catalog); the base never imports a wing; team planners
    (team/) compose single-robot ones and nothing single-robot imports them."""
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    (contract,) = [c for c in config["contracts"] if c.get("containers") == ["pipeline.planners"]]
    order = [set(name.strip() for name in layer.split("|")) for layer in contract["layers"]]
    rank = {name: i for i, layer in enumerate(order) for name in layer}
    assert (
        rank["team"] < rank["catalog"] < rank["extensions"] < rank["guide"] == rank["baselines"] < rank["graph_planner"]
    )
    planners = ROOT / "pipeline" / "planners"
    parts = {
        path.stem if path.is_file() else path.name
        for path in planners.iterdir()
        if (path.suffix == ".py" and path.stem != "__init__") or (path / "__init__.py").is_file()
    }
    assert parts <= set(rank), sorted(parts - set(rank))  # every module of planners/ has its place


def test_every_subpackage_is_in_a_layer():
    config = tomllib.loads((ROOT / "pyproject.toml").read_text())["tool"]["importlinter"]
    (contract,) = [c for c in config["contracts"] if c["type"] == "layers" and "containers" not in c]
    layered = {name.strip() for layer in contract["layers"] for name in layer.split("|")}
    packages = {f"pipeline.{path.parent.name}" for path in (ROOT / "pipeline").glob("*/__init__.py")}
    top_modules = {f"pipeline.{path.stem}" for path in (ROOT / "pipeline").glob("*.py") if path.stem != "__init__"}
    assert packages | top_modules <= layered, sorted((packages | top_modules) - layered)


def test_no_project_module_is_imported_inside_a_function():
    """Function-local imports are for heavy or optional packages (torch, ray, matplotlib), never to hide a cycle."""
    found = []
    for module in all_modules():
        path = module_path(module)
        tree = ast.parse(path.read_text(), str(path))
        for function in (n for n in ast.walk(tree) if isinstance(n, (ast.FunctionDef, ast.AsyncFunctionDef))):
            for node in ast.walk(function):
                names = (
                    [a.name for a in node.names]
                    if isinstance(node, ast.Import)
                    else [node.module or ""]
                    if isinstance(node, ast.ImportFrom)
                    else []
                )
                found += [
                    f"{path.relative_to(ROOT)}:{node.lineno} {name}"
                    for name in names
                    if name.split(".")[0] in ("pipeline", "stages")
                ]
    assert not found, found


def _modules_loaded(code: str, cwd) -> set[str]:
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-c", code + "\nimport sys; print(' '.join(sorted(sys.modules)))"],
        cwd=cwd,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-2000:]
    return set(done.stdout.strip().splitlines()[-1].split())


def test_drawing_mazes_never_loads_torch(tmp_path):
    """`guide mazes` and the generate_mazes stage need no model: starting them must not cost torch's import."""
    cli = (
        "from pipeline.cli import app\n"
        "app(['mazes', '--out', 'm', '--count', '1', '--side', '50'], standalone_mode=False)"
    )
    loaded = _modules_loaded(cli, tmp_path)
    assert "pipeline.cli.maps" in loaded and "torch" not in loaded
    params = yaml.safe_load((ROOT / "params.yaml").read_text())
    params["mazes"]["train"]["count"] = params["mazes"]["test"]["count"] = 1
    params["mazes"]["offices"]["count"] = 1
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    loaded = _modules_loaded("from stages.generate_mazes import main\nmain('params.yaml')", tmp_path)
    assert "stages.generate_mazes" in loaded and "torch" not in loaded
