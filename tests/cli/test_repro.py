"""`guide repro`: `dvc repro` that goes on where a killed run's lock entries would stop it."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

from pipeline.cli.repro import clear_stale_locks, drop_stale_entries, holder_is_alive

ENV = {**os.environ, "DVC_NO_ANALYTICS": "1"}


def dvc_project(folder: Path) -> Path:
    """A git + DVC project with one stage that writes out.txt."""
    folder.mkdir()
    subprocess.run(["git", "init", "-q"], cwd=folder, check=True)
    subprocess.run(["dvc", "init", "-q"], cwd=folder, check=True, env=ENV)
    (folder / "dvc.yaml").write_text("stages:\n  make:\n    cmd: echo made > out.txt\n    outs:\n      - out.txt\n")
    return folder


def killed_runs_lock(project: Path, pid: int, cmd: str) -> None:
    """The rwlock a `dvc repro` killed while running stage `make` leaves, naming process `pid`."""
    entry = {"pid": pid, "cmd": cmd}
    lock = {"write": {str(project / "out.txt"): entry}, "read": {str(project / "dvc.yaml"): [entry]}}
    (project / ".dvc/tmp").mkdir(parents=True, exist_ok=True)
    (project / ".dvc/tmp/rwlock").write_text(json.dumps(lock))


def test_a_lock_whose_process_id_was_reused_stops_dvc_and_not_guide_repro(tmp_path):
    """After a restart the dead run's process id belongs to another process (here: this test's)."""
    project = dvc_project(tmp_path / "p")
    killed_runs_lock(project, os.getpid(), "/usr/bin/dvc repro")
    refused = subprocess.run(["dvc", "repro"], cwd=project, env=ENV, capture_output=True, text=True)
    assert refused.returncode != 0 and "is busy" in refused.stderr + refused.stdout
    guide = Path(sys.executable).with_name("guide")
    run = subprocess.run([str(guide), "repro"], cwd=project, env=ENV, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout + run.stderr
    assert "cleared the lock of a killed run on 2 path(s)" in run.stderr
    assert (project / "out.txt").read_text() == "made\n"
    assert not any(json.loads((project / ".dvc/tmp/rwlock").read_text()).values())  # no entry left


def command_once_started(pid: int, marker: str) -> str:
    """The command line of process `pid` once it has exec'd (before that it is still its parent's)."""
    deadline = time.monotonic() + 30
    while time.monotonic() < deadline:
        cmd = " ".join(psutil.Process(pid).cmdline())
        if marker in cmd:
            return cmd
        time.sleep(0.01)
    raise AssertionError(f"process {pid} did not start {marker!r} within 30 s")


def test_a_live_runs_entries_are_kept(tmp_path):
    live = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(600)"])
    try:
        cmd = command_once_started(live.pid, "time.sleep(600)")
        assert holder_is_alive({"pid": live.pid, "cmd": cmd})
        assert not holder_is_alive({"pid": live.pid, "cmd": "dvc repro"})  # the id, another command
        lock = {
            "write": {"a": {"pid": live.pid, "cmd": cmd}, "b": {"pid": os.getpid(), "cmd": "dvc repro"}},
            "read": {"c": [{"pid": live.pid, "cmd": cmd}, {"pid": os.getpid(), "cmd": "dvc repro"}]},
        }
        assert sorted(drop_stale_entries(lock)) == ["b", "c"]
        assert lock == {"write": {"a": {"pid": live.pid, "cmd": cmd}}, "read": {"c": [{"pid": live.pid, "cmd": cmd}]}}
        project = dvc_project(tmp_path / "p")
        killed_runs_lock(project, live.pid, cmd)
        assert clear_stale_locks(project) == []  # a live run keeps its lock
    finally:
        live.kill()
        live.wait()
    assert not holder_is_alive({"pid": live.pid, "cmd": cmd})  # gone now


def test_guide_repro_outside_a_dvc_project_says_so(tmp_path):
    guide = Path(sys.executable).with_name("guide")
    run = subprocess.run([str(guide), "repro"], cwd=tmp_path, env=ENV, capture_output=True, text=True)
    assert run.returncode != 0 and "is not a DVC project" in run.stderr


@pytest.mark.parametrize("text", ["{not json"])
def test_a_corrupt_lock_file_is_reported(tmp_path, text):
    project = dvc_project(tmp_path / "p")
    (project / ".dvc/tmp").mkdir(parents=True, exist_ok=True)
    (project / ".dvc/tmp/rwlock").write_text(text)
    guide = Path(sys.executable).with_name("guide")
    run = subprocess.run([str(guide), "repro"], cwd=project, env=ENV, capture_output=True, text=True)
    assert run.returncode != 0 and ".dvc/tmp/rwlock" in run.stderr
