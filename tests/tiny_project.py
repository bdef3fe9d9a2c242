"""A fresh copy of the project with the tiny profile: what the end-to-end DVC tests run on.

`make_tiny_project(dest)` copies the git-tracked files, shrinks every stage to seconds, and
commits the copy (DVC's experiments need a commit). `dvc(project, *args)` runs DVC in it.
"""

from __future__ import annotations

import os
import queue
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import yaml
from import_graph import ROOT


def git(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        ["git", "-c", "user.name=ci", "-c", "user.email=ci@example.com", *args],
        cwd=cwd,
        check=True,
        capture_output=True,
        text=True,
    )


def dvc_env() -> dict[str, str]:
    """The environment for DVC in a copy: no analytics, MLflow's store the copy's own."""
    env = {**os.environ, "DVC_NO_ANALYTICS": "1", "MLFLOW_DISABLE_TELEMETRY": "true"}
    env.pop("MLFLOW_TRACKING_URI", None)
    return env


def dvc(project: Path, *args: str, check: bool = False) -> subprocess.CompletedProcess:
    run = subprocess.run(["dvc", *args], cwd=project, env=dvc_env(), capture_output=True, text=True)
    if check:
        assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
    return run


def tiny_params(params: dict[str, Any], protocol: dict[str, Any] | None = None) -> dict[str, Any]:
    """`params` (the parsed params.yaml) shrunk so that `dvc repro` takes a few minutes."""
    params["protocol"].update(protocol or {})
    params["mazes"]["train"]["count"] = 2
    params["mazes"]["test"]["count"] = 2
    params["mazes"]["test"]["side_m"] = [50, 50]
    params["mazes"]["train"]["side_m"] = [50, 60]
    params["collect_pairs"].update(pairs=12, pairs_per_shard=6, stop_steps=[3, 10])
    params["collect_expert"].update(episodes=2, episodes_per_shard=1)
    params["mazes"]["offices"]["count"] = 2
    params["fit_gate"].update(maps=2, holdout_maps=1, offices=2, office_holdout=1, hidden=[4])
    params["train_inpainter"].update(max_epochs=2, batch_size=4)
    params["build_observations"].update(max_nodes=64)
    params["train_planner"]["model"].update(max_nodes=64, d_model=32, heads=2, encoder_layers=1, denoiser_layers=1)
    params["train_planner"]["train"].update(
        max_epochs=2, batch_size=16, warmup_steps=2
    )  # 2: a checkpoint to resume from
    params["report"].update(k_values=[2, 4], k_maps=1)
    params["train_block_model"].update(mazes=3, holdout_mazes=1, side_m=50.0, epochs=2, model={"width": 8, "groups": 4})
    params["train_drl"].update(
        model={"max_nodes": 32, "d_model": 16, "heads": 2, "encoder_layers": 1},
        timesteps=128,
        checkpoint_every=32,
        eval_mazes=1,
        eval_side_m=50,
    )
    params["train_drl"]["env"].update(maze_sides_m=[50], max_steps=30)
    params["train_drl"]["ppo"].update(n_envs=2, n_steps=32, batch_size=32, n_epochs=1)
    params["train_drl"]["imitation"].update(episodes=2, epochs=1, dagger_rounds=1, dagger_episodes=1, dagger_epochs=1)
    params["distil_policy"].update(teacher_episodes=2, episodes=1, episodes_per_shard=1, eval_mazes=2, eval_side_m=50)
    params["distil_policy"]["train"].update(max_epochs=1, batch_size=16, warmup_steps=2)
    # The shipped drl policy was trained at the default protocol: its row is the benchmark's, not this copy's.
    params["benchmark"]["planners"] = [p for p in params["benchmark"]["planners"] if not p.startswith("drl_shipped=")]
    params["benchmark"].update(robots=[1, 2], team_planners=["greedy_utility", "guide_tsp"])
    return params


def make_tiny_project(dest: Path, protocol: dict[str, Any] | None = None) -> Path:
    """A committed copy of the project's tracked files at `dest`, with the tiny profile in its params.yaml."""
    if shutil.which("dvc") is None:
        raise AssertionError("dvc is a dependency of the project and must be installed")
    tracked = subprocess.run(["git", "ls-files"], cwd=ROOT, check=True, capture_output=True, text=True).stdout.split()
    for name in tracked:
        if (ROOT / name).is_file():
            (dest / name).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(ROOT / name, dest / name)
    params = tiny_params(yaml.safe_load((dest / "params.yaml").read_text()), protocol)
    (dest / "params.yaml").write_text(yaml.safe_dump(params, sort_keys=False))
    git(dest, "init", "-q")
    git(dest, "add", "-A")
    git(dest, "commit", "-qm", "copy")
    return dest


RUNNING = re.compile(r"Running stage '([^']+)'")


def streamed_repro(
    project: Path,
    on_stage: Callable[[str], Callable[[], bool] | None] = lambda stage: None,
    log: list[str] | None = None,
    args: tuple[str, ...] = (),
    env: dict[str, str] | None = None,
) -> tuple[bool, str | None, dict[str, float]]:
    """`guide repro [args]`, streamed: at each stage's start `on_stage(stage)` may give a condition, and once
    it holds the run is SIGKILLed with its whole process group. Returns (finished, the stage
    killed in, seconds per stage); the output goes to `log`."""
    guide = str(Path(sys.executable).with_name("guide"))
    run = subprocess.Popen(
        [guide, "repro", *args],
        cwd=project,
        env=env or dvc_env(),
        stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT,
        text=True,
        start_new_session=True,
    )
    lines: queue.Queue[str | None] = queue.Queue()

    def read() -> None:
        for line in run.stdout:  # type: ignore[union-attr]
            lines.put(line)
        lines.put(None)

    threading.Thread(target=read, daemon=True).start()
    stage, condition, started, seconds, output = None, None, time.monotonic(), {}, []
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
            if stage is not None:
                seconds[stage] = time.monotonic() - started
            stage, started = match.group(1), time.monotonic()
            condition = on_stage(stage)
        if condition is not None and condition():
            os.killpg(run.pid, signal.SIGKILL)
            run.wait()
            if log is not None:
                log.append(f"--- killed in {stage}\n" + "".join(output))
            return False, stage, seconds
    run.wait()
    if stage is not None:
        seconds[stage] = time.monotonic() - started
    if log is not None:
        log.append("".join(output))
    assert run.returncode == 0, "".join(output)[-4000:]
    return True, None, seconds


@dataclass(frozen=True)
class TinyRun:
    """A tiny copy after one uninterrupted `dvc repro` on the process engine: what it printed and
    how long each stage took (what the chaos test times its kills by)."""

    project: Path
    output: str
    seconds: dict[str, float]


def tiny_reference_run(dest: Path) -> TinyRun:
    """A fresh tiny copy at `dest` and its uninterrupted run, on the process engine whatever this
    machine's GUIDE_BACKEND and RAY_ADDRESS say."""
    project = make_tiny_project(dest)
    env = {k: v for k, v in dvc_env().items() if k not in ("GUIDE_BACKEND", "RAY_ADDRESS")}
    log: list[str] = []
    _, _, seconds = streamed_repro(project, log=log, env=env)
    return TinyRun(project, log[-1], seconds)
