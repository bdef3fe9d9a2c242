"""docs/environment.md's examples are the scripts in examples/, and they run."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import pytest
from import_graph import ROOT

DOC = (ROOT / "docs" / "environment.md").read_text()


def doc_examples() -> dict[str, str]:
    """{script: the python block the doc shows after naming it}."""
    found = re.findall(r"`(examples/[a-z_]+\.py)`[^\n]*\n(?:[^\n]*\n)*?```python\n(.*?)```", DOC, flags=re.S)
    return dict(found)


def run_example(script: str, *args: str) -> str:
    done = subprocess.run(
        [sys.executable, str(ROOT / script), *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert done.returncode == 0, done.stderr[-3000:]
    return done.stdout


def test_the_doc_shows_the_example_scripts_as_they_are():
    examples = doc_examples()
    assert set(examples) == {"examples/random_agent.py", "examples/train_maskable_ppo.py"}
    for script, block in examples.items():
        assert block == (ROOT / script).read_text(), script


def test_the_random_agent_runs():
    out = run_example("examples/random_agent.py", "--episodes", "1", "--side", "50")
    assert re.search(r"maze_\d+: reward -?[\d.]+, \d+ m, \d+% explored, (complete|truncated) after \d+ steps", out), out


def test_the_maskable_ppo_example_trains_and_drives():
    pytest.importorskip("sb3_contrib")
    out = run_example("examples/train_maskable_ppo.py", "--timesteps", "256", "--max-steps", "20")
    assert re.search(r"maze_\d+: reward -?[\d.]+, \d+ m, \d+% explored in \d+ steps", out), out
