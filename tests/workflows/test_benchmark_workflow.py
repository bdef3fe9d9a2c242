"""The benchmark stage's folder, reports/benchmark/: replaced as a whole, or left as it was."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from pipeline.evaluation import benchmark as evaluation
from pipeline.workflows import benchmark as workflow
from pipeline.world.protocol import Protocol

SECTION = {"planners": ["nearest_frontier"], "workers": 1, "seed": 0, "speed_mps": 1.0}


def files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def leftovers(root: Path) -> list[str]:
    return sorted(str(p.relative_to(root)) for p in root.rglob(".*"))


@pytest.fixture
def workspace(small_maze_path, tmp_path, monkeypatch):
    """A working directory with one test maze; no MLflow (log_benchmark is its own test's)."""
    (tmp_path / "data/mazes/test").mkdir(parents=True)
    shutil.copy(small_maze_path, tmp_path / "data/mazes/test/small.png")
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(workflow, "log_benchmark", lambda *args, **kwargs: [])
    return tmp_path


def test_the_benchmark_folder_is_replaced_as_a_whole_or_not_at_all(workspace, monkeypatch):
    out = workspace / "reports/benchmark"
    workflow.benchmark_test_mazes(workflow.Settings.model_validate(SECTION), Protocol())
    first = files(out)
    assert {
        "metrics.csv",
        "summary.md",
        "run.json",
        "exploration.csv",
        "coverage.png",
        "nearest_frontier/small.csv",
        "nearest_frontier/small.steps.csv",
    } <= set(first)
    (out / "retired").mkdir()
    (out / "retired/small.csv").write_text("x,y\n0,0\n")  # a planner an earlier run had
    before = files(out)
    metrics = (workspace / "reports/benchmark.json").read_bytes()

    written: list[Path] = []
    real = evaluation.write_steps_csv

    def dies_on_the_second_episode(path, rows):
        if written:
            raise OSError("killed")
        written.append(Path(path))
        return real(path, rows)

    monkeypatch.setattr(evaluation, "write_steps_csv", dies_on_the_second_episode)
    two = {**SECTION, "planners": ["nearest_frontier", "greedy_utility"]}
    with pytest.raises(OSError, match="killed"):
        workflow.benchmark_test_mazes(workflow.Settings.model_validate(two), Protocol())
    assert written and written[0].parent.parent != out  # the first episode went to the temporary folder
    assert files(out) == before
    assert (workspace / "reports/benchmark.json").read_bytes() == metrics
    assert leftovers(workspace) == []
    kept = workspace / "checkpoints/benchmark"  # outside the folder DVC deletes before it reruns the stage
    assert list(kept.glob("item_*.pkl"))  # the episodes finished before the kill, for the rerun

    monkeypatch.setattr(evaluation, "write_steps_csv", real)
    workflow.benchmark_test_mazes(workflow.Settings.model_validate(two), Protocol())
    after = files(out)
    assert not any(name.startswith("retired/") for name in after)
    assert {"greedy_utility/small.csv", "nearest_frontier/small.csv"} <= set(after)
    assert after["nearest_frontier/small.csv"] == first["nearest_frontier/small.csv"]
    assert set(json.loads((workspace / "reports/benchmark.json").read_text())) == {"nearest_frontier", "greedy_utility"}
    assert leftovers(workspace) == [] and not kept.exists()
