"""A benchmark killed halfway and run again: what the resume tests of both engines share."""

from __future__ import annotations

import pandas as pd
import pytest


def twelve_mazes(folder):
    """12 small generated mazes (50 m), for the kill-and-resume benchmarks."""
    import numpy as np

    from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png

    folder.mkdir(parents=True, exist_ok=True)
    for i in range(12):
        write_maze_png(
            generate_maze(MazeConfig(side_m=(50.0, 50.0)), np.random.default_rng([11, i])), folder / f"m{i:02d}.png"
        )
    return folder


def killed_and_resumed(tmp_path, extra_args=(), env_extra=None):
    """`guide benchmark` of 12 mazes x 3 planners SIGKILLed (with its process group) once about half
    the episodes are kept, then the same command again; (how many were kept, the rerun's output,
    the finished metrics frame, an uninterrupted run's metrics frame)."""
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    mazes = twelve_mazes(tmp_path / "mazes")
    guide = str(Path(sys.executable).with_name("guide"))
    env = {**os.environ, "MLFLOW_DISABLE_TELEMETRY": "true", **(env_extra or {})}
    command = [
        guide,
        "benchmark",
        "--maps",
        str(mazes),
        "--planner",
        "nearest_frontier",
        "--planner",
        "greedy_utility",
        "--planner",
        "tare",
        "--workers",
        "2",
        "--no-mlflow",
        *extra_args,
    ]
    out = tmp_path / "killed"
    run = subprocess.Popen(
        [*command, "--out", str(out)],
        cwd=tmp_path,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        start_new_session=True,
    )
    deadline = time.monotonic() + 300
    while time.monotonic() < deadline and run.poll() is None and len(list(out.glob(".episodes/item_*.pkl"))) < 18:
        time.sleep(0.05)
    if run.poll() is not None:
        pytest.fail("the benchmark ended before it was killed:\n" + run.stderr.read()[-2000:])
    os.killpg(run.pid, signal.SIGKILL)
    run.wait()
    kept = len(list(out.glob(".episodes/item_*.pkl")))
    again = subprocess.run([*command, "--out", str(out)], cwd=tmp_path, env=env, capture_output=True, text=True)
    assert again.returncode == 0, again.stderr[-3000:]
    whole = subprocess.run(
        [*command, "--out", str(tmp_path / "whole")], cwd=tmp_path, env=env, capture_output=True, text=True
    )
    assert whole.returncode == 0, whole.stderr[-3000:]
    return (
        kept,
        again.stdout + again.stderr,
        pd.read_csv(out / "metrics.csv"),
        pd.read_csv(tmp_path / "whole/metrics.csv"),
    )
