"""examples/own_planner.py registers a planner that the simulator, the registry and the spec
language take like ours, and it explores a maze."""

from __future__ import annotations

import os
import subprocess
import sys

from import_graph import ROOT

from pipeline.planners import make_planner, registry
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode


def test_the_example_planner_explores_a_maze(small_maze, small_maze_path, monkeypatch):
    monkeypatch.setattr(registry, "_REGISTRY", dict(registry._REGISTRY))  # the example's name stays in this test
    monkeypatch.delitem(sys.modules, "own_planner", raising=False)
    sys.path.insert(0, str(ROOT / "examples"))
    try:
        import own_planner  # noqa: F401  (registers best_ratio)
    finally:
        sys.path.remove(str(ROOT / "examples"))
    result = run_episode(small_maze, make_planner("best_ratio"), Protocol(), seed=0)
    assert result.complete and result.motion_violations == 0
    done = subprocess.run(
        [sys.executable, str(ROOT / "examples" / "own_planner.py"), str(small_maze_path)],
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.startswith("best_ratio: complete after ")
