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
    return {
        dep
        for dep in deps
        if dep.startswith("stages/") or (dep.startswith("pipeline/") and not dep.startswith("pipeline/assets"))
    }


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


def test_machine_settings_are_not_part_of_any_stages_identity():
    """Each stage lists its section's keys one by one, all but the machine settings: a teammate
    with another core count (workers), devices or threads does not rerun anything."""
    from pipeline.common.params import MACHINE_KEYS

    params = yaml.safe_load((ROOT / "params.yaml").read_text())
    for name, stage in yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"].items():
        listed = stage.get("params") or stage.get("do", {}).get("params") or []
        for section, values in params.items():
            if not isinstance(values, dict):
                continue
            keys = {entry.split(".", 1)[1] for entry in listed if entry.startswith(section + ".")}
            if section in listed:
                assert not set(values) & set(MACHINE_KEYS), f"{name}: lists all of {section}, machine settings too"
            elif keys and any(k in values for k in MACHINE_KEYS):
                assert keys == set(values) - set(MACHINE_KEYS), (
                    f"{name}: lists {sorted(keys)} of {section}, not every key but the machine settings "
                    f"{sorted(set(values) - set(MACHINE_KEYS) - keys)}"
                )


def test_every_output_travels_through_a_dvc_remote_or_git():
    """An output DVC does not cache must be a summary JSON that git tracks: anything else (a
    figure, a folder of tables) would be missing from a teammate's clone after `dvc pull`."""
    import re
    import subprocess

    paths = yaml.safe_load((ROOT / "pipeline/paths.yaml").read_text())
    for name, stage in yaml.safe_load((ROOT / "dvc.yaml").read_text())["stages"].items():
        for out in stage.get("outs") or stage.get("do", {}).get("outs") or []:
            if isinstance(out, dict):
                ((path, options),) = out.items()
                if options.get("cache") is False:
                    ref = re.fullmatch(r"\$\{(\w+)\.(\w+)\}", path)
                    resolved = str(paths[ref[1]][ref[2]]) if ref and ref[1] != "item" else path
                    assert resolved.endswith(".json") or resolved == "${item.metrics}", (name, resolved)
                    if ref and ref[1] != "item":
                        ignored = subprocess.run(["git", "check-ignore", "-q", resolved], cwd=ROOT).returncode == 0
                        assert not ignored, f"{name}: {resolved} is neither cached by DVC nor tracked by git"
