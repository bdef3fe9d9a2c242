"""A fresh copy of the project with the tiny profile: what the end-to-end DVC tests run on.

`make_tiny_project(dest)` copies the git-tracked files, shrinks every stage to seconds, and
commits the copy (DVC's experiments need a commit). `dvc(project, *args)` runs DVC in it.
"""

from __future__ import annotations

import os
import shutil
import subprocess
from pathlib import Path
from typing import Any

import yaml

from import_graph import ROOT


def git(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run(["git", "-c", "user.name=ci", "-c", "user.email=ci@example.com", *args], cwd=cwd, check=True,
                          capture_output=True, text=True)


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
    params["train_planner"]["train"].update(max_epochs=2, batch_size=16, warmup_steps=2)  # 2: a checkpoint to resume from
    params["report"].update(k_values=[2, 4], k_maps=1)
    params["train_block_model"].update(mazes=3, holdout_mazes=1, side_m=50.0, epochs=2, model={"width": 8, "groups": 4})
    params["train_drl"].update(model={"max_nodes": 32, "d_model": 16, "heads": 2, "encoder_layers": 1}, timesteps=128,
                               checkpoint_every=32, eval_mazes=1, eval_side_m=50)
    params["train_drl"]["env"].update(maze_sides_m=[50], max_steps=30)
    params["train_drl"]["ppo"].update(n_envs=2, n_steps=32, batch_size=32, n_epochs=1)
    params["train_drl"]["imitation"].update(episodes=2, epochs=1, dagger_rounds=1, dagger_episodes=1, dagger_epochs=1)
    params["distil_policy"].update(teacher_episodes=2, episodes=1, episodes_per_shard=1, eval_mazes=2, eval_side_m=50)
    params["distil_policy"]["train"].update(max_epochs=1, batch_size=16, warmup_steps=2)
    # The shipped drl policy was trained at the default protocol: its row is the benchmark's, not this copy's.
    params["benchmark"]["planners"] = [p for p in params["benchmark"]["planners"] if not p.startswith("drl_shipped=")]
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
