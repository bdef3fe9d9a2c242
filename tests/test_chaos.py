"""Chaos: `dvc repro` killed with SIGKILL inside every stage, with its whole process group, then
run again as the README says (`guide repro`), until it finishes.

On the tiny profile. Each stage is killed once, part-way through its own work where it has some
(a collection after its first shard, a training after its first checkpoint, a per-map stage after
its first map), else at a random share of the time it took in an uninterrupted run (once more,
forced and sooner, if it ran faster than that). Then:
- the final data sets are byte for byte those of an uninterrupted `dvc repro` (DVC's hashes);
- every training killed after a checkpoint resumed from it (epochs add up, none restarted);
- the collections kept the shards they had finished;
- `dvc status` is clean: the lock describes what is on disk.
After each kill the process ids the dead run left in DVC's `.dvc/tmp/rwlock` are handed to a live
process (this test's), as after a restart that reuses them, where a plain `dvc repro` refuses.
"""

from __future__ import annotations

import json
import os
import re
import time
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
import yaml
from tiny_project import dvc, make_tiny_project, streamed_repro

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
    "distil_policy": "checkpoints/distil/round_0/shards/shard_*.json",
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
    "distil_policy": "kept from an earlier run",
}


def kill_condition(project: Path, stage: str, seconds: float, rng: np.random.Generator) -> Callable[[], bool]:
    """When to kill `stage`, which starts now: once its own progress is on disk; for a stage that
    leaves none, at a random moment of the `seconds` it took in the uninterrupted run."""
    pattern = PROGRESS.get(stage)
    wall, start, patience = time.time(), time.monotonic(), float(rng.uniform(0.1, 0.7)) * seconds
    if pattern is not None:
        return lambda: (
            any(path.stat().st_mtime >= wall for path in project.glob(pattern)) and stage_running(project, stage)
        )
    return lambda: time.monotonic() - start > patience and stage_running(project, stage)


def stage_running(project: Path, stage: str) -> bool:
    """Whether the stage's own command still runs in `project`: a kill after it ended would land in
    DVC's own bookkeeping (writing dvc.lock is not atomic in DVC), which is not what this test is
    about. (Other projects' stages, of tests beside this one, run in other folders.)"""
    words = ["stages." + stage.split("@")[0], *(["--variant", stage.split("@")[1]] if "@" in stage else [])]
    for cmdline in Path("/proc").glob("[0-9]*/cmdline"):
        try:
            text = cmdline.read_bytes().replace(b"\0", b" ").decode(errors="replace")
            cwd = Path(os.readlink(cmdline.with_name("cwd")))
        except OSError:
            continue
        if all(word in text for word in words) and "pytest" not in text and cwd == project.resolve():
            return True
    return False


def reuse_dead_process_ids(project: Path) -> None:
    """Give the process ids in `.dvc/tmp/rwlock` to a live process, this test's, as a restarted
    machine or container would: DVC then takes the killed run for a live one."""
    path = project / ".dvc/tmp/rwlock"
    if not path.is_file():
        return
    lock = json.loads(path.read_text())
    for entry in [*lock.get("write", {}).values(), *(e for entries in lock.get("read", {}).values() for e in entries)]:
        entry["pid"] = os.getpid()
    path.write_text(json.dumps(lock))


def stage_is_done(project: Path, stage: str) -> bool:
    """Whether DVC recorded `stage` as done (its lock entry matches what is on disk)."""
    status = dvc(project, "status", stage, check=True)
    return "up to date" in status.stdout.lower()


def data_hashes(project: Path) -> dict[str, str]:
    """DVC's recorded hash of every data output (data/*), from the project's dvc.lock."""
    lock = yaml.safe_load((project / "dvc.lock").read_text())
    return {
        out["path"]: out["md5"]
        for stage in lock["stages"].values()
        for out in stage.get("outs", [])
        if out["path"].startswith("data/")
    }


@pytest.mark.slow
@pytest.mark.xdist_group("e2e")  # beside the other tests of the shared tiny run
def test_dvc_repro_killed_inside_every_stage_ends_as_an_uninterrupted_run(tiny_reference, tmp_path):
    reference, seconds = tiny_reference.project, dict(tiny_reference.seconds)
    project = make_tiny_project(tmp_path / "chaos")
    rng = np.random.default_rng(49)
    killed: list[str] = []
    log: list[str] = []

    def kill_once(stage: str) -> Callable[[], bool] | None:
        return None if stage in killed else kill_condition(project, stage, seconds[stage], rng)

    args: tuple[str, ...] = ()
    for _ in range(4 * len(seconds)):
        finished, stage, _ = streamed_repro(project, kill_once, log, args)
        args = ()
        if not finished:
            if stage_is_done(project, stage):  # the kill came after the stage had ended: not inside it
                log.append(log.pop().replace(f"--- killed in {stage}\n", f"--- killed after {stage}\n", 1))
                seconds[stage] /= 3
                args = ("--force", "--single-item", stage)
            else:
                killed.append(stage)
            reuse_dead_process_ids(project)
            continue
        missed = sorted(set(seconds) - set(killed))
        if not missed:
            break
        # It ran faster than in the uninterrupted run (a busy machine): once more, forced, killed sooner.
        seconds[missed[0]] /= 3
        args = ("--force", "--single-item", missed[0])
    else:
        pytest.fail("dvc repro never finished:\n" + log[-1][-3000:])
    assert sorted(killed) == sorted(seconds), f"not killed: {sorted(set(seconds) - set(killed))}"
    # After each kill, the next run of that stage took its work up again.
    text = "\n".join(log)
    for stage in killed:
        after = text.split(f"--- killed in {stage}\n", 1)[1]
        parts = after.split(f"Running stage '{stage}'", 2)
        if len(parts) < 3:  # DVC did not run it again (restored it, or the kill came as it ended)
            assert stage not in RESUMED, f"{stage} was not run again after its kill:\n{after[-3000:]}"
            continue
        rerun = parts[2].split("Running stage", 1)[0]
        said = [line.strip() for line in re.split(r"[\r\n]", rerun) if re.search(r"kept|resuming|continuing", line)]
        print(f"{stage}: killed {'at its progress marker' if stage in PROGRESS else 'part-way'}; rerun: {said[:1]}")
        if stage in RESUMED:
            assert RESUMED[stage] in rerun, (stage, rerun[-2000:])
    assert data_hashes(project) == data_hashes(reference)
    status = dvc(project, "status", check=True)
    assert "up to date" in status.stdout.lower() or not status.stdout.strip(), status.stdout
