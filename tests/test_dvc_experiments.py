"""DVC experiments compare: the one metrics file (reports/metrics.json) and the stages' summary JSONs
are git-tracked, so `dvc exp show` and `dvc metrics diff` read them in every commit and experiment.

`check_experiments(project)` runs on a tiny-profile copy after its `dvc repro` (the end-to-end test
calls it, so that no second repro is paid for); the other tests read dvc.yaml and .gitignore only.
"""

from __future__ import annotations

import json
import re
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import yaml
from import_graph import ROOT
from tiny_project import dvc, git

from pipeline.planners.specs import parse_planner_spec

HEADLINE = "reports/metrics.json"
HEADLINE_GROUPS = {"precision", "seconds", "distil"}
PLANNER_KEYS = {"distance_m", "gap_pct", "vs_greedy_pct", "vs_greedy_ci95_pct"}


def _resolve(path: str, variables: dict[str, Any], item: dict[str, Any] | None = None) -> str:
    """A dvc.yaml path with its ${group.name} (and a foreach's ${item.name}) filled in from pipeline/paths.yaml."""

    def value(match: re.Match) -> str:
        node: Any = {**variables, "item": item or {}}
        for part in match.group(1).split("."):
            node = node[part]
        return str(node)

    return re.sub(r"\$\{([^}]+)\}", value, path)


def dvc_outputs(root: Path = ROOT) -> Iterator[tuple[str, str, dict[str, Any]]]:
    """(kind, path, options) of every output in dvc.yaml: kind "outs" or "metrics"; foreach stages once per item."""
    variables = yaml.safe_load((root / "pipeline/paths.yaml").read_text())
    for stage in yaml.safe_load((root / "dvc.yaml").read_text())["stages"].values():
        body, items = (stage["do"], list(variables["policies"].values())) if "foreach" in stage else (stage, [None])
        for item in items:
            for kind in ("outs", "metrics"):
                for entry in body.get(kind) or []:
                    path, options = next(iter(entry.items())) if isinstance(entry, dict) else (entry, {})
                    yield kind, _resolve(path, variables, item), options or {}


def test_the_headline_file_is_the_only_metrics_file():
    metrics = [(path, options) for kind, path, options in dvc_outputs() if kind == "metrics"]
    assert metrics == [(HEADLINE, {"cache": False})]
    assert yaml.safe_load((ROOT / "pipeline/paths.yaml").read_text())["reports"]["headline"] == HEADLINE


def test_git_tracks_exactly_the_uncached_json_outputs():
    """.gitignore lets through the headline and each stage's summary JSON (cache: false outputs), and
    nothing else of reports/: figures and folders stay DVC's or nobody's."""
    outputs = list(dvc_outputs())
    tracked = sorted(path for _, path, options in outputs if path.endswith(".json") and options.get("cache") is False)
    others = sorted(path for _, path, _ in outputs if path not in tracked and path.startswith("reports/"))
    assert HEADLINE in tracked and "reports/report.json" in tracked and others
    done = subprocess.run(
        ["git", "check-ignore", "--no-index", *tracked, *others], cwd=ROOT, capture_output=True, text=True, check=False
    )  # exit status 1 when nothing is ignored
    ignored = set(done.stdout.split())
    assert not ignored & set(tracked), f".gitignore hides {sorted(ignored & set(tracked))}"
    assert ignored == set(others), f".gitignore lets through {sorted(set(others) - ignored)}"


def _revisions(shown: list[dict[str, Any]]) -> Iterator[dict[str, Any]]:
    """Every row of `dvc exp show --json`: the workspace, the baseline commit and its experiments."""
    for row in shown:
        yield row
        for experiment in row.get("experiments") or []:
            yield from _revisions(experiment.get("revs") or [])


def _headline_of(row: dict[str, Any]) -> dict[str, Any]:
    files = (row.get("data") or {}).get("metrics") or {}
    assert HEADLINE in files, (row.get("rev"), row.get("name"), sorted(files))
    entry = files[HEADLINE]
    assert not entry.get("error") and entry.get("data"), (row.get("rev"), row.get("name"), entry)
    return entry["data"]


def _test_count(row: dict[str, Any]) -> int:
    return row["data"]["params"]["params.yaml"]["data"]["mazes"]["test"]["count"]


def check_headline(metrics: dict[str, Any], planners: set[str], steps: list[int]) -> None:
    """Every benchmark planner's headline numbers, Table I's precision and the stage times, all numbers
    (Table I has no precision at a step where nothing was predicted, as on the tiny profile's small mazes)."""
    assert planners | {"seconds"} <= set(metrics) <= planners | HEADLINE_GROUPS, sorted(
        metrics
    )  # DVC drops an empty group
    for planner in planners:
        assert set(metrics[planner]) <= PLANNER_KEYS and "distance_m" in metrics[planner], (planner, metrics[planner])
    assert set(metrics.get("precision", {})) <= {f"step{step}" for step in steps}, metrics["precision"]
    assert {"collect_pairs", "train_inpainter", "train_planner@guide", "train_planner@dare"} <= set(metrics["seconds"])
    values = [value for group in metrics.values() for value in group.values()]
    assert all(isinstance(value, (int, float)) for value in values), metrics


def check_experiments(project: Path) -> None:
    """After `dvc repro` on a tiny copy: commit it as the baseline, run one experiment with another
    test-maze count, and `dvc exp show` / `dvc metrics diff` carry both headlines, no value missing."""
    params = yaml.safe_load((project / "params.yaml").read_text())
    planners = {parse_planner_spec(spec).label for spec in params["benchmark"]["planners"]}
    steps = params["eval_predictor"]["steps"]
    check_headline(json.loads((project / HEADLINE).read_text()), planners, steps)

    # git sees, under reports/, exactly the headline and the stages' summary JSONs
    status = git(project, "status", "--porcelain", "--untracked-files=all").stdout.splitlines()
    in_reports = {line[3:] for line in status if line[3:].startswith("reports/")}
    tracked = {
        path for _, path, options in dvc_outputs(project) if path.endswith(".json") and options.get("cache") is False
    }
    assert in_reports == tracked, sorted(in_reports ^ tracked)
    git(project, "add", "-A")
    git(project, "commit", "-qm", "tiny baseline")

    dvc(project, "exp", "run", "-S", "mazes.test.count=3", check=True)
    shown = json.loads(dvc(project, "exp", "show", "--json", check=True).stdout)
    rows = list(_revisions(shown))
    workspace = next(row for row in rows if row["rev"] == "workspace")
    baseline = next(row for row in shown if row["rev"] != "workspace")  # the commit the experiment started from
    experiments = [row for row in rows if row is not workspace and row is not baseline]
    assert len(experiments) == 1, [(row["rev"], row.get("name")) for row in rows]
    (experiment,) = experiments
    assert (_test_count(baseline), _test_count(experiment)) == (2, 3)
    for row in (workspace, baseline, experiment):
        check_headline(_headline_of(row), planners, steps)
    assert _headline_of(experiment)["optimal"]["distance_m"] != _headline_of(baseline)["optimal"]["distance_m"]
    assert _headline_of(workspace) == _headline_of(experiment)  # `dvc exp run` leaves its results in the workspace

    diff = json.loads(dvc(project, "metrics", "diff", "--json", check=True).stdout)  # HEAD (the baseline) -> workspace
    assert "optimal.distance_m" in diff.get(HEADLINE, {}), diff
    assert "mazes.test.count" in dvc(project, "params", "diff", check=True).stdout
