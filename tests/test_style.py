"""The code passes ruff's lint rules (pyproject's `[tool.ruff.lint]`)."""

from __future__ import annotations

import shutil
import subprocess

import pytest
from import_graph import ROOT


def test_ruff_finds_nothing():
    ruff = shutil.which("ruff")
    if ruff is None:
        pytest.fail("ruff is not installed: pip install -e '.[dev]'")
    done = subprocess.run([ruff, "check", "--no-cache", "."], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout[-3000:]
