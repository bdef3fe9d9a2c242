"""Team trajectory files: `time_s,robot,x,y` rows (the starts first) and the merges beside them
under a range, written atomically and read back with an error naming the file and line.
"""

from __future__ import annotations

import csv
import math
from pathlib import Path
from typing import Sequence

from pipeline.common.atomic import atomic_file

TEAM_COLUMNS = ["time_s", "robot", "x", "y"]


MERGE_COLUMNS = ["time_s", "robots"]
TEAM_SUFFIX = ".team.csv"
MERGES_SUFFIX = ".team.merges.csv"
MAX_ROBOTS = 8  # robots a team file may name (0-7)


def _number(value: float, decimals: int = 6) -> str:
    text = f"{value:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def write_team_csv(path: str | Path, rows: Sequence[tuple[float, int, float, float]], speed_mps: float = 1.0) -> Path:
    """The team trajectory file: `time_s,robot,x,y`, one row per arrival in time order, the starts
    first (time 0, robots 0..N-1); times at `speed_mps`."""
    path = Path(path)
    with atomic_file(path) as tmp, tmp.open("w", newline="") as handle:
        handle.write(",".join(TEAM_COLUMNS) + "\n")
        for t, robot, x, y in rows:
            handle.write(f"{_number(t / speed_mps)},{int(robot)},{_number(x)},{_number(y)}\n")
    return path


def write_merges_csv(path: str | Path, merges: Sequence[tuple[float, tuple[int, ...]]], speed_mps: float = 1.0) -> Path:
    """The merges beside a team file under a range: `time_s,robots` (robots joined by `+`)."""
    path = Path(path)
    with atomic_file(path) as tmp, tmp.open("w", newline="") as handle:
        handle.write(",".join(MERGE_COLUMNS) + "\n")
        for t, group in merges:
            handle.write(f"{_number(t / speed_mps)},{'+'.join(str(k) for k in group)}\n")
    return path


def merges_path(team_file: str | Path) -> Path:
    team_file = Path(team_file)
    return team_file.with_name(team_file.name.removesuffix(TEAM_SUFFIX) + MERGES_SUFFIX)


def read_team_csv(path: str | Path) -> list[tuple[float, int, float, float]]:
    """Read a team trajectory file; ValueError naming the file and the line for a bad one: the
    header, four numbers a row (robot a whole number 0-7), times never going back, the starts
    first (time 0, robots 0, 1, ... in order), every robot of the team at least in the starts."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: file not found")
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            lines = list(csv.reader(handle))
    except (UnicodeDecodeError, csv.Error) as error:
        raise ValueError(f"{path}: not a readable CSV file ({error})") from None
    if not lines or [c.strip() for c in lines[0]] != TEAM_COLUMNS:
        raise ValueError(f"{path}: a team trajectory file starts with the header {','.join(TEAM_COLUMNS)}")
    rows: list[tuple[float, int, float, float]] = []
    starts_done = False
    for number, line in enumerate(lines[1:], start=2):
        if not line:
            continue
        try:
            t, robot, x, y = float(line[0]), line[1].strip(), float(line[2]), float(line[3])
            if len(line) != 4:
                raise ValueError
        except (ValueError, IndexError):
            raise ValueError(f"{path}: line {number} is not time_s,robot,x,y: {','.join(line)[:80]!r}") from None
        if not robot.isdigit() or int(robot) >= MAX_ROBOTS:
            raise ValueError(f"{path}: line {number}: robot must be a whole number 0-{MAX_ROBOTS - 1}, got {robot!r}")
        if not all(math.isfinite(v) for v in (t, x, y)) or t < 0:
            raise ValueError(f"{path}: line {number}: time and position must be finite, time >= 0")
        if rows and t < rows[-1][0]:
            raise ValueError(f"{path}: line {number}: time {t:g} s goes back (the rows are in time order)")
        robot_id = int(robot)
        if not starts_done:
            if t == 0 and robot_id == len(rows):
                rows.append((t, robot_id, x, y))
                continue
            starts_done = True
        if robot_id >= team_size(rows):
            raise ValueError(f"{path}: line {number}: robot {robot_id} has no start row (the starts come first)")
        rows.append((t, robot_id, x, y))
    if not rows:
        raise ValueError(f"{path}: no rows (the starts come first, one per robot)")
    return rows


def team_size(rows: Sequence[tuple[float, int, float, float]]) -> int:
    """Robots in a team file: the start rows, robots 0, 1, ... at time 0."""
    size = 0
    for t, robot, _, _ in rows:
        if t == 0 and robot == size:
            size += 1
        else:
            break
    return size
