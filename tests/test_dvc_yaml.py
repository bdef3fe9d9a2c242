"""dvc.yaml's code dependencies are what each stage's code imports, so a stage reruns when its code changes."""

from __future__ import annotations

import yaml

from import_graph import ROOT, closure, code_unit


def stage_commands() -> dict[str, str]:
    stages = yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"]
    return {name: (stage.get("cmd") or stage["do"]["cmd"]) for name, stage in stages.items()}


def code_deps(name: str) -> set[str]:
    stages = yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"]
    stage = stages[name]
    deps = stage.get("deps") or stage["do"]["deps"]
    return {dep for dep in deps if dep.startswith("stages/") or (dep.startswith("pipeline/") and not dep.startswith("pipeline/assets"))}


def test_every_stage_depends_on_exactly_the_code_it_imports():
    for name, cmd in stage_commands().items():
        module = cmd.split()[2]  # python -m stages.<name>
        assert module.startswith("stages."), (name, cmd)
        imported = {code_unit(m) for m in closure(module)}
        declared = code_deps(name)
        assert not imported - declared, f"{name}: dvc.yaml misses {sorted(imported - declared)}"
        assert not declared - imported, f"{name}: dvc.yaml lists code it never imports: {sorted(declared - imported)}"


def test_every_data_model_and_report_path_is_written_down_once():
    """dvc.yaml names its paths through pipeline/paths.yaml's vars, and no module spells one out."""
    import re

    text = (ROOT / "dvc.yaml").read_text()
    assert "pipeline/paths.yaml" in yaml.safe_load(text)["vars"]
    literal = re.findall(r"^\s*- (?:data|models|reports)/\S*", text, flags=re.M)
    assert not literal, f"dvc.yaml spells out paths that pipeline/paths.yaml holds: {literal}"
    spelled = []
    for path in list((ROOT / "pipeline").rglob("*.py")) + list((ROOT / "stages").glob("*.py")):
        for number, line in enumerate(path.read_text().splitlines(), 1):
            if re.search(r"""Path\(\s*f?["'](?:data|models|reports)/""", line):
                spelled.append(f"{path.relative_to(ROOT)}:{number}")
    assert not spelled, f"paths written outside pipeline/paths.yaml: {spelled}"
