"""Trajectory and metrics files in docs/protocol.md's layout (what outside checks replay)."""

from __future__ import annotations

import csv
import os
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

METRICS_COLUMNS = [
    "map",
    "planner",
    "distance_m",
    "steps",
    "complete",
    "explored_ratio",
    "decision_ms_median",
    "decision_ms_p95",
    "seed",
]


def _format_metres(value: float) -> str:
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def write_trajectory_csv(path: str | Path, trajectory: Sequence[Sequence[float]]) -> Path:
    """Write waypoints as `x,y` rows in metres, first row the start (0, 0)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", newline="") as handle:
        handle.write("x,y\n")
        for x, y in trajectory:
            handle.write(f"{_format_metres(float(x))},{_format_metres(float(y))}\n")
    os.replace(tmp, path)
    return path


def read_trajectory_csv(path: str | Path) -> np.ndarray:
    """Read a trajectory file; raises ValueError naming the file and the problem."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: file not found")
    with path.open(newline="") as handle:
        rows = list(csv.reader(handle))
    if not rows or [c.strip() for c in rows[0]] != ["x", "y"]:
        raise ValueError(f"{path}: a trajectory file starts with the header 'x,y'")
    points = []
    for number, row in enumerate(rows[1:], start=2):
        if not row:
            continue
        try:
            x, y = (float(v) for v in row)
        except ValueError:
            raise ValueError(f"{path}: line {number} is not two numbers: {','.join(row)!r}") from None
        points.append((x, y))
    if not points:
        raise ValueError(f"{path}: no waypoint rows (the first row must be the start 0,0)")
    return np.array(points, dtype=np.float64)


def write_metrics_csv(path: str | Path, rows: Iterable[dict]) -> Path:
    """Write metrics.csv with docs/protocol.md's columns, in that order."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    with tmp.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=METRICS_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow(row)
    os.replace(tmp, path)
    return path
