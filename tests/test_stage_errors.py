"""Stages run as `python -m stages.<name>` (what `dvc repro` runs) fail on user errors with one line."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import pytest

from pipeline.world.maps import MapError
from pipeline.planners.registry import UnknownPlannerError
from pipeline.stage_errors import UPSTREAM_HINT, run_stage_main, user_error_message

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize(
    "error, message",
    [
        (FileNotFoundError("data/mazes/test: not a directory"), "data/mazes/test: not a directory" + UPSTREAM_HINT),
        (FileNotFoundError("models/x.pt: no export; run the train stage first"), "models/x.pt: no export; run the train stage first"),
        (FileNotFoundError("my.png not found"), "my.png not found"),
        (MapError("a.png", "no free cell"), "a.png: no free cell"),
        (ValueError("tau must be in (0, 1)"), "tau must be in (0, 1)"),
        (SystemExit("error: nothing to do"), "nothing to do"),
        (SystemExit(0), None),
        (UnknownPlannerError("unknown planner 'foo'; choose from: dare"), "unknown planner 'foo'; choose from: dare"),
        (KeyError("bug"), None),
        (ZeroDivisionError(), None),
    ],
)
def test_user_error_message(error, message):
    assert user_error_message(error) == message


def test_run_stage_main_prints_one_line_and_exits_2(capsys):
    def missing(path):
        raise FileNotFoundError(f"{path}: not a directory")

    with pytest.raises(SystemExit) as exit_info:
        run_stage_main(missing, "data/mazes/train")
    assert exit_info.value.code == 2
    assert capsys.readouterr().err == f"error: data/mazes/train: not a directory{UPSTREAM_HINT}\n"
    assert run_stage_main(lambda a, b: a + b, 2, 3) == 5
    with pytest.raises(KeyError):  # a bug keeps its traceback
        run_stage_main(lambda: {}["x"])


def test_python_m_stage_without_inputs_is_one_error_line(tmp_path):
    (tmp_path / "params.yaml").write_text((ROOT / "params.yaml").read_text())
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    done = subprocess.run([sys.executable, "-m", "stages.train_planner"], cwd=tmp_path, env=env,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 2, done.stderr
    assert done.stderr.strip().splitlines() == [
        "error: data/observations/guide.npz: no observations; run the build_observations stage first"
    ]
