"""Fuzzed params files: every bad setting of every stage is one `error:` line naming its key.

From the project's own params.yaml, each case changes one setting of a stage's section (or of the
shared `protocol` section, for the stages that read it): a negative number, NaN, inf, a value of
the wrong type, a deleted key, an added unknown key, an empty list, an unknown planner name. The
stage's `main` runs as `run_stage_main` runs it, in a fresh folder holding only the fuzzed file,
with its workflow replaced by one that raises `Accepted`: so a setting the stage lets through is
seen without the work being done. A refused one must be exit status 2, exactly one stderr line
`error: ...` that names the dotted key, no traceback, and no file written.

`python -m pytest tests/stages/test_params_fuzz.py -m slow -s` runs every case and prints the
counts per stage and outcome; the normal run takes a seeded sample.
"""

from __future__ import annotations

import copy
import importlib
import math
import os
import random
import re
import subprocess
import sys
from collections import Counter
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator

import pytest
import yaml
from import_graph import ROOT

from pipeline.stage_runner import run_stage_main

UNKNOWN_KEY = "zz_not_a_setting"
UNKNOWN_PLANNER = "no_such_planner"


class Accepted(Exception):
    """Raised by the stand-in workflow: the stage accepted its settings and went on to work."""


@dataclass(frozen=True)
class Stage:
    """A stage as the fuzz runs it: its module, section, whether it reads `protocol`, the name (in
    the module) of the first call that does work, and the arguments of its `main` after the file."""

    module: str
    section: str
    protocol: bool
    workflow: str
    args: tuple = ()

    @property
    def name(self) -> str:
        return self.module + (f"[{self.args[0]}]" if self.args else "")


STAGES = [
    Stage("generate_mazes", "mazes", True, "_write_map_sets"),  # the first call that touches data/
    Stage("import_plans", "plans", False, "import_plan_folder"),  # reads no protocol: the plans name their own cells
    Stage("fit_gate", "fit_gate", True, "fit_gate"),
    Stage("train_block_model", "train_block_model", True, "train_the_block_model"),
    Stage("train_drl", "train_drl", True, "train_the_drl_policy"),
    Stage("benchmark", "benchmark", True, "benchmark_test_mazes"),
    Stage("collect_pairs", "collect_pairs", True, "collect_pairs"),
    Stage("collect_expert", "collect_expert", True, "collect_expert"),
    Stage("train_inpainter", "train_inpainter", True, "train_and_report"),
    Stage("eval_predictor", "eval_predictor", True, "predictor_folder"),
    Stage("build_observations", "build_observations", True, "build_observations"),
    Stage("train_planner", "train_planner", False, "train_and_report", ("guide",)),  # reads no protocol
    Stage("train_planner", "train_planner", False, "train_and_report", ("dare",)),
    Stage("report", "report", True, "write_report"),
]

# Mutations the code that reads the key truly accepts: (key pattern, mutation). Each is a meaning
# the settings already had before these checks, kept as it was.
ALLOWED = {
    # The protocol's every value has a default (Protocol's fields); stage tests write `protocol: {}`.
    ("protocol.*", "delete"),
    # door_graph is on, off or null (on below a 2 m lattice): a bool is one of its values.
    ("protocol.door_graph", "bool"),
    # generate_mazes reads these with MazeConfig's defaults, and no office floors without `offices`.
    ("mazes.block_m", "delete"),
    ("mazes.rooms", "delete"),
    ("mazes.room_blocks", "delete"),
    ("mazes.extra_loops", "delete"),
    ("mazes.offices", "delete"),
    # train_inpainter reads its section with TrainConfig's and InpainterConfig's defaults
    # (params_section, not complete_section; tests/training/test_train_inpainter.py writes a partial one).
    ("train_inpainter.*", "delete"),
    # A model mapping names only the fields it changes from the config's defaults (tests/tiny_project.py).
    ("train_drl.model.*", "delete"),
    ("train_block_model.model.*", "delete"),
    ("train_planner.model.*", "delete"),
    # The map kinds and office sizes default to the maze benchmark's (older params files lack them).
    ("mazes.office_scale", "delete"),
    ("mazes.train.kind", "delete"),
    ("mazes.test.kind", "delete"),
    # No plans_share: no floors drawn from the imported plans (params files from before the plans).
    ("mazes.train.plans_share", "delete"),
    ("mazes.test.plans_share", "delete"),
    # No plans_exclude (params files from before the folds), or an empty one: no plan left out.
    ("mazes.train.plans_exclude", "delete"),
    ("mazes.test.plans_exclude", "delete"),
    ("mazes.train.plans_exclude", "empty list"),
    ("mazes.test.plans_exclude", "empty list"),
    # Lightning's devices may be a list of device indices.
    ("train_inpainter.devices", "list"),
    ("train_planner.devices", "list"),
    # PPOSettings takes any finite entropy and value coefficients (stable-baselines3 does).
    ("train_drl.ppo.ent_coef", "negative"),
    ("train_drl.ppo.vf_coef", "negative"),
    # An empty list has a meaning: a logistic gate; no threshold sweep; no denoising-steps sweep.
    ("fit_gate.hidden", "empty list"),
    ("eval_predictor.sweep_thresholds", "empty list"),
    ("report.k_values", "empty list"),
    ("report.k_planners", "empty list"),
    # Params files from before the teams and the gate's draw: no team runs, one shared belief, all samples.
    ("benchmark.robots", "delete"),
    ("benchmark.team_planners", "delete"),
    ("benchmark.comm_range_m", "delete"),
    ("fit_gate.fit_samples", "delete"),
    # No team sizes or no team planners: no team runs.
    ("benchmark.robots", "empty list"),
    ("benchmark.team_planners", "empty list"),
    # Benchmark labels, not registered names: one absent from the benchmark shows as "not run".
    ("report.ablation_planners[*]", "unknown planner"),
    ("report.figure_planners[*]", "unknown planner"),
}


def matches(path: str, pattern: str) -> bool:
    """`path` fits `pattern`, where `*` stands for any text (and `[`, `]` are themselves)."""
    return re.fullmatch(re.escape(pattern).replace(r"\*", ".*"), path) is not None


def allowed(path: str, mutation: str) -> bool:
    return any(kind == mutation and matches(path, pattern) for pattern, kind in ALLOWED)


@dataclass(frozen=True)
class Case:
    """One fuzzed params file: the stage, the dotted key changed, the mutation, the key an error must name."""

    stage: Stage
    path: str
    mutation: str
    named: str
    params: Any

    def __str__(self) -> str:
        return f"{self.stage.name}: {self.path} {self.mutation}"


def bad_values(value: Any, key: str) -> Iterator[tuple[str, Any]]:
    """(mutation, value) for one leaf value."""
    if isinstance(value, bool):
        yield from (("number", 1), ("string", "yes"))
    elif isinstance(value, (int, float)):
        yield from (
            ("negative", -abs(value) - 1),
            ("nan", math.nan),
            ("inf", math.inf),
            ("string", "abc"),
            ("bool", True),
        )
    elif isinstance(value, str):
        yield from (("number", 7), ("bool", True), ("empty string", ""))
        if "planner" in key:
            yield "unknown planner", UNKNOWN_PLANNER
    elif value is None:  # a null that names a default: never a negative number or NaN
        yield from (("negative", -1), ("nan", math.nan), ("bool", True))
    if isinstance(value, list):
        yield from (("empty list", []), ("string", "abc"), ("number", 3), ("dict", {"a": 1}))
    elif isinstance(value, dict):
        yield from (("string", "abc"), ("number", 3), ("list", [1]))
    else:
        yield from (("list", [value]), ("dict", {"a": value}))


def mutations(tree: Any, path: str, key: str) -> Iterator[tuple[str, str, str, Any]]:
    """(dotted path, mutation, key the error must name, how to apply) over a tree of settings.

    Applying is a function of the section's copy; list items name their list (a check may refuse
    the item or the list as a whole)."""
    for mutation, value in bad_values(tree, key):
        yield path, mutation, path, ("set", value)
    if isinstance(tree, dict):
        yield f"{path}.{UNKNOWN_KEY}", "unknown key", f"{path}.{UNKNOWN_KEY}", ("set child", UNKNOWN_KEY)
        for child, value in tree.items():
            yield f"{path}.{child}", "delete", f"{path}.{child}", ("delete", child)
            for sub_path, mutation, named, action in mutations(value, f"{path}.{child}", child):
                yield sub_path, mutation, named, ("in", child, action)
    elif isinstance(tree, list):
        for index, value in enumerate(tree):
            for sub_path, mutation, _, action in mutations(value, f"{path}[{index}]", key):
                yield sub_path, mutation, path, ("item", index, action)


def apply(tree: Any, action: tuple) -> Any:
    """`tree` (a deep copy) with one mutation applied; the new tree."""
    kind = action[0]
    if kind == "set":
        return action[1]
    if kind == "set child":
        tree[action[1]] = 1
        return tree
    if kind == "delete":
        del tree[action[1]]
        return tree
    if kind == "in":
        tree[action[1]] = apply(tree[action[1]], action[2])
        return tree
    tree[action[1]] = apply(tree[action[1]], action[2])  # item
    return tree


def fuzz_cases() -> list[Case]:
    """Every case of every stage, from the project's params.yaml."""
    base = yaml.safe_load((ROOT / "params.yaml").read_text())
    cases = []
    for stage in STAGES:
        sections = [stage.section] + (["protocol"] if stage.protocol else [])
        for section in sections:
            for path, mutation, named, action in mutations(base[section], section, section):
                if path == section and mutation not in ("string", "list"):  # the section itself: two kinds suffice
                    continue
                params = copy.deepcopy(base)
                params[section] = apply(params[section], action)
                cases.append(Case(stage, path, mutation, named, params))
    return cases


CASES = fuzz_cases()


def run_case(case: Case, folder: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture) -> str:
    """The case's outcome: "error" (checked here), "accepted" or "traceback: ..."."""
    folder.mkdir()
    (folder / "params.yaml").write_text(yaml.safe_dump(case.params, sort_keys=False))
    module = importlib.import_module(f"stages.{case.stage.module}")

    def accept(*args: Any, **kwargs: Any) -> None:
        raise Accepted

    with monkeypatch.context() as patch:
        patch.chdir(folder)
        patch.setattr(module, case.stage.workflow, accept)
        capsys.readouterr()
        try:
            run_stage_main(module.main, "params.yaml", *case.stage.args)
        except Accepted:
            outcome = "accepted"
        except SystemExit as exit_info:
            outcome = "error" if exit_info.code == 2 else f"traceback: exit {exit_info.code!r}"
        except Exception as error:  # a traceback: the stage runner let it through
            outcome = f"traceback: {type(error).__name__}: {error}"
        err = capsys.readouterr().err
    written = sorted(str(p.relative_to(folder)) for p in folder.rglob("*") if p.name != "params.yaml")
    if outcome == "error":
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: params.yaml: "), (str(case), err)
        assert case.named in lines[0], (str(case), lines[0])
        assert "Traceback" not in err
    assert not written, (str(case), written)
    return outcome


def check_cases(
    cases: list[Case], tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture
) -> Counter:
    counts: Counter = Counter()
    problems = []
    for number, case in enumerate(cases):
        outcome = run_case(case, tmp_path / f"case{number}", monkeypatch, capsys)
        expected_accept = allowed(case.path, case.mutation)
        label = "allowed" if outcome == "accepted" and expected_accept else outcome
        counts[(case.stage.name, label if not label.startswith("traceback") else "traceback")] += 1
        if outcome.startswith("traceback") or (outcome == "accepted") != expected_accept:
            problems.append(f"{case}: {outcome}" + (" (allow-listed, yet refused)" if expected_accept else ""))
    assert not problems, "\n".join(problems)
    return counts


def report(counts: Counter) -> str:
    stages = sorted({stage for stage, _ in counts})
    kinds = ("error", "allowed", "traceback")
    lines = [f"{'stage':<28}{'files':>7}" + "".join(f"{kind:>11}" for kind in kinds)]
    for stage in stages:
        row = [counts[(stage, kind)] for kind in kinds]
        lines.append(f"{stage:<28}{sum(row):>7}" + "".join(f"{n:>11}" for n in row))
    total = [sum(counts[(stage, kind)] for stage in stages) for kind in kinds]
    lines.append(f"{'all':<28}{sum(total):>7}" + "".join(f"{n:>11}" for n in total))
    return "\n".join(lines)


def test_the_fuzz_covers_every_stage_and_mutation():
    assert len(CASES) >= 1000
    assert {case.stage.name for case in CASES} == {stage.name for stage in STAGES}
    kinds = {case.mutation for case in CASES}
    assert {
        "negative",
        "nan",
        "inf",
        "string",
        "number",
        "bool",
        "list",
        "dict",
        "delete",
        "unknown key",
        "empty list",
        "unknown planner",
    } <= kinds
    # every allow-list entry is used by some case (a stale entry would hide nothing, but mislead)
    for pattern, kind in ALLOWED:
        assert any(case.mutation == kind and matches(case.path, pattern) for case in CASES), (pattern, kind)


def test_a_sample_of_fuzzed_params_is_refused_by_name(tmp_path, monkeypatch, capsys):
    sample = random.Random(2026).sample(CASES, 150)
    counts = check_cases(sample, tmp_path, monkeypatch, capsys)
    assert sum(counts.values()) == 150


@pytest.mark.slow
def test_every_fuzzed_params_file_is_refused_by_name(tmp_path, monkeypatch, capsys):
    counts = check_cases(CASES, tmp_path, monkeypatch, capsys)
    with capsys.disabled():
        print(f"\nfuzzed params files: {len(CASES)}\n{report(counts)}")


def test_the_default_params_and_profiles_pass_every_stage_check(tmp_path, monkeypatch, capsys):
    """The checks refuse nothing a shipped params file holds: each stage goes on to its work."""
    for name in ("params.yaml", "profiles/paper.yaml", "profiles/real_robot.yaml"):
        params = yaml.safe_load((ROOT / name).read_text())
        for number, stage in enumerate(STAGES):
            case = Case(stage, name, "none", "", params)
            assert run_case(case, tmp_path / f"{Path(name).stem}{number}", monkeypatch, capsys) == "accepted", case


# Real runs of `python -m stages.<name> --params FILE` (what dvc.yaml runs), for stages that fail fast.
SUBPROCESS_CASES = [
    ("generate_mazes", "mazes.train.count", "negative", "mazes.train.count"),
    ("benchmark", "benchmark.planners[2]", "unknown planner", "benchmark.planners[2]"),
    ("collect_pairs", "collect_pairs.workers", "string", "collect_pairs.workers"),
    pytest.param(
        "train_drl", "train_drl.ppo.learning_rate", "nan", "train_drl.ppo.learning_rate", marks=pytest.mark.slow
    ),
    pytest.param("report", "report.zz_not_a_setting", "unknown key", "report.zz_not_a_setting", marks=pytest.mark.slow),
]


@pytest.mark.parametrize(("module", "path", "mutation", "named"), SUBPROCESS_CASES)
def test_the_command_line_prints_one_error_line(tmp_path, module, path, mutation, named):
    case = next(c for c in CASES if c.stage.module == module and c.path == path and c.mutation == mutation)
    (tmp_path / "fuzzed.yaml").write_text(yaml.safe_dump(case.params, sort_keys=False))
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run(
        [sys.executable, "-m", f"stages.{module}", "--params", "fuzzed.yaml"],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    lines = done.stderr.strip().splitlines()
    assert done.returncode == 2, done.stderr
    assert len(lines) == 1 and lines[0].startswith("error: fuzzed.yaml: ") and named in lines[0], lines
    assert sorted(p.name for p in tmp_path.iterdir()) == ["fuzzed.yaml"]
