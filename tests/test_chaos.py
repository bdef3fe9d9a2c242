"""Chaos: `dvc repro` killed with SIGKILL inside every stage, then run again, until it finishes.

On the tiny profile. Each stage is killed once, part-way through its own work where it has some
(a collection after its first shard, a training after its first checkpoint, a per-map stage after
its first map, a folder output while it is being filled), else a moment after it starts. Then:
- the final data sets are byte for byte those of an uninterrupted `dvc repro` (DVC's hashes);
- every training killed after a checkpoint resumed from it (epochs add up, none restarted);
- the collections kept the shards they had finished;
- `dvc status` is clean: the lock describes what is on disk.
"""

from __future__ import annotations

import os
import queue
import re
import signal
import subprocess
import threading
import time
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
import yaml

from tiny_project import dvc, dvc_env, make_tiny_project

# Where each stage's own progress shows on disk (relative to the project): killed once it exists.
PROGRESS = {
    "fit_gate": "checkpoints/gate_samples/item_*.pkl",
    "train_block_model": "checkpoints/block_model/last.pt",
    "train_drl": "checkpoints/drl/last.zip",
    "collect_pairs": "checkpoints/pairs/shard_*.json",
    "collect_expert": "checkpoints/expert/shard_*.json",
    "train_inpainter": "checkpoints/inpainter/last.ckpt",
    "build_observations": "checkpoints/observations/item_*.pkl",
    "train_planner@guide": "checkpoints/planner_guide/last.ckpt",
    "train_planner@dare": "checkpoints/planner_dare/last.ckpt",
}
# What the rerun after such a kill must say it did.
RESUMED = {
    "fit_gate": "kept from an interrupted run",
    "train_block_model": "resuming from checkpoints/block_model/last.pt",
    "train_drl": "continuing from the checkpoint at",
    "collect_pairs": "kept from an earlier run",
    "collect_expert": "kept from an earlier run",
    "train_inpainter": "resuming from checkpoints/inpainter/last.ckpt",
    "build_observations": "kept from an interrupted run",
    "train_planner@guide": "resuming from checkpoints/planner_guide/last.ckpt",
    "train_planner@dare": "resuming from checkpoints/planner_dare/last.ckpt",
}
RUNNING = re.compile(r"Running stage '([^']+)'")


def partial_output(project: Path) -> bool:
    """A folder or file output being written under its temporary name (`pipeline.common.atomic`)."""
    return any(".partial-" in path.name for top in ("data", "models", "reports") for path in (project / top).rglob(".*"))


def kill_condition(project: Path, stage: str, rng: np.random.Generator) -> Callable[[], bool]:
    """When to kill `stage`, which starts now: once its own progress is on disk, or a folder output
    is half made, or (a stage with neither) at a random moment of its first seconds."""
    pattern = PROGRESS.get(stage)
    wall, start, patience = time.time(), time.monotonic(), float(rng.uniform(0.5, 3.0))
    if pattern is not None:
        return lambda: any(path.stat().st_mtime >= wall for path in project.glob(pattern))
    return lambda: partial_output(project) or time.monotonic() - start > patience


def repro_killing(project: Path, killed: dict[str, str], rng: np.random.Generator, log: list[str]) -> bool:
    """One `dvc repro`, SIGKILLed (with everything it started) inside the first stage not yet killed;
    True when it ran to the end instead."""
    run = subprocess.Popen(["dvc", "repro"], cwd=project, env=dvc_env(), stdout=subprocess.PIPE,
                           stderr=subprocess.STDOUT, text=True, start_new_session=True)
    lines: queue.Queue[str | None] = queue.Queue()

    def read() -> None:
        for line in run.stdout:  # type: ignore[union-attr]
            lines.put(line)
        lines.put(None)

    threading.Thread(target=read, daemon=True).start()
    stage, condition, output = None, None, []
    while True:
        try:
            line = lines.get(timeout=0.05)
        except queue.Empty:
            line = ""
        if line is None:
            break
        output.append(line)
        match = RUNNING.search(line)
        if match:
            stage = match.group(1)
            condition = kill_condition(project, stage, rng) if stage not in killed else None
        if condition is not None and condition():
            os.killpg(run.pid, signal.SIGKILL)
            run.wait()
            killed[stage] = "at its progress marker" if stage in PROGRESS else "part-way"
            log.append(f"--- killed in {stage}\n" + "".join(output[-5:]))
            return False
    run.wait()
    log.append("".join(output))
    assert run.returncode == 0, "".join(output)[-4000:]
    return True


def data_hashes(project: Path) -> dict[str, str]:
    """DVC's recorded hash of every data output (data/*), from the project's dvc.lock."""
    lock = yaml.safe_load((project / "dvc.lock").read_text())
    return {out["path"]: out["md5"] for stage in lock["stages"].values() for out in stage.get("outs", [])
            if out["path"].startswith("data/")}


@pytest.mark.slow
def test_dvc_repro_killed_inside_every_stage_ends_as_an_uninterrupted_run(tmp_path):
    reference = make_tiny_project(tmp_path / "reference")
    dvc(reference, "repro", check=True)
    project = make_tiny_project(tmp_path / "chaos")
    rng = np.random.default_rng(49)
    killed: dict[str, str] = {}
    log: list[str] = []
    for _ in range(40):
        if repro_killing(project, killed, rng, log):
            break
    else:
        pytest.fail("dvc repro never finished:\n" + "\n".join(log[-3:]))
    every_stage = {name for name in yaml.safe_load((reference / "dvc.lock").read_text())["stages"]}
    assert set(killed) == every_stage, f"not killed: {sorted(every_stage - set(killed))}"
    # After each kill, the next run of that stage took its work up again.
    text = "\n".join(log)
    for stage, words in RESUMED.items():
        after = text.split(f"--- killed in {stage}\n", 1)[1]
        rerun = after.split(f"Running stage '{stage}'", 1)[1].split("Running stage", 1)[0]
        assert words in rerun, (stage, rerun[-2000:])
    assert data_hashes(project) == data_hashes(reference)
    status = dvc(project, "status", check=True)
    assert "up to date" in status.stdout.lower() or not status.stdout.strip(), status.stdout
