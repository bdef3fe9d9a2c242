"""Trajectory and metrics files in docs/protocol.md's layout (what outside checks replay)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from pipeline.common.atomic import atomic_file
from pipeline.world.map_files import is_file_named  # the loaders' check, shared: a bad file name is not an OSError
from pipeline.world.simulator import LATTICE_TOLERANCE_M  # the tolerance replay uses for the start

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
    "reachable_share",
    "fallbacks",
    "early_stop",
]
# The per-step record beside a trajectory (OUT/<label>/<map>.steps.csv): one row per trajectory
# row up to completion, the start first (docs/protocol.md, "Per-step files").
STEP_COLUMNS = ["step", "distance_m", "explored_m2", "explored_share", "decision_ms", "prediction_trust", "fallback"]
# Files written before `prediction_trust` (a predicting planner's trust in its predictions, empty
# for other planners) or before `fallback` (1 where the whole building's fallback sent the robot)
# read as having them empty.
LEGACY_STEP_COLUMNS = (STEP_COLUMNS[:5], STEP_COLUMNS[:6])
STEPS_SUFFIX = ".steps.csv"
MAX_COORDINATE_M = 1e9  # a waypoint farther than this (a million km) is a malformed file, not a move


def _format_number(value: float | None, decimals: int = 6) -> str:
    """A number with at most `decimals` decimals and no trailing zeros; empty for None or NaN (a
    per-step file's decision time a replay does not measure)."""
    if value is None or not math.isfinite(value):
        return ""
    text = f"{value:.{decimals}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _flag(value: bool | None) -> str:
    """1 / 0 for a recorded yes / no, empty where nothing was recorded (a replay)."""
    return "" if value is None else str(int(bool(value)))


def write_trajectory_csv(path: str | Path, trajectory: Sequence[Sequence[float]]) -> Path:
    """Write waypoints as `x,y` rows in metres, first row the start (0, 0)."""
    path = Path(path)
    with atomic_file(path) as tmp, tmp.open("w", newline="") as handle:
        handle.write("x,y\n")
        for x, y in trajectory:
            handle.write(f"{_format_number(float(x))},{_format_number(float(y))}\n")
    return path


def _is_dir(path: Path) -> bool:
    """Path.is_dir that says False (not raises) for a name the OS rejects, as map_files.is_file_named does."""
    try:
        return path.is_dir()
    except (OSError, ValueError):
        return False


def _quote(row: Sequence[str]) -> str:
    """A CSV row as quoted text, cut short for a one-line error."""
    text = ",".join(row)
    return repr(text if len(text) <= 80 else text[:77] + "...")


def read_trajectory_csv(path: str | Path) -> np.ndarray:
    """Read a trajectory file; raises ValueError naming the file and the problem.

    Refused: a missing file or a folder, text that is not UTF-8 (a leading byte-order mark,
    as Excel writes, is fine), a header other than `x,y`, a row that is not two finite numbers
    of at most MAX_COORDINATE_M metres, no waypoint rows, or a first row that is not the start 0,0.
    """
    path = Path(path)
    if _is_dir(path):
        raise ValueError(f"{path}: is a folder, not a trajectory file (pass one CSV file)")
    if not is_file_named(path):
        raise ValueError(f"{path}: file not found")
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            reader = csv.reader(handle)
            rows = [(reader.line_num, row) for row in reader]  # line_num: the row's (last) line
    except UnicodeDecodeError as error:
        raise ValueError(
            f"{path}: not a UTF-8 text file (byte 0x{error.object[error.start]:02x} at offset {error.start}); "
            "a trajectory file is a CSV with the header 'x,y'"
        ) from None
    except csv.Error as error:  # a NUL byte, a field over the csv module's size limit
        raise ValueError(f"{path}: not a readable CSV file ({error})") from None
    except OSError as error:
        raise ValueError(f"{path}: cannot read the file ({error.strerror or type(error).__name__})") from None
    if not rows or [c.strip() for c in rows[0][1]] != ["x", "y"]:
        raise ValueError(f"{path}: a trajectory file starts with the header 'x,y'")
    points: list[tuple[float, float]] = []
    for number, row in rows[1:]:
        if not row:
            continue
        try:
            x, y = (float(v) for v in row)
        except ValueError:
            raise ValueError(f"{path}: line {number} is not two numbers: {_quote(row)}") from None
        if not (math.isfinite(x) and math.isfinite(y)):
            raise ValueError(f"{path}: line {number} is not two finite numbers: {_quote(row)}")
        if abs(x) > MAX_COORDINATE_M or abs(y) > MAX_COORDINATE_M:
            raise ValueError(f"{path}: line {number} has a coordinate beyond ±{MAX_COORDINATE_M:,.0f} m: {_quote(row)}")
        if not points and (abs(x) > LATTICE_TOLERANCE_M or abs(y) > LATTICE_TOLERANCE_M):
            raise ValueError(f"{path}: line {number}: the first row must be the start 0,0, got {_quote(row)}")
        points.append((x, y))
    if not points:
        raise ValueError(f"{path}: no waypoint rows (the first row must be the start 0,0)")
    return np.array(points, dtype=np.float64)


def write_metrics_csv(path: str | Path, rows: Iterable[dict]) -> Path:
    """Write metrics.csv with docs/protocol.md's columns, in that order."""
    path = Path(path)
    with atomic_file(path) as tmp, tmp.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=METRICS_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        for row in rows:
            writer.writerow(row)
    return path


def steps_path(trajectory: str | Path) -> Path:
    """The per-step file beside a trajectory file: OUT/label/map.csv -> OUT/label/map.steps.csv."""
    trajectory = Path(trajectory)
    return trajectory.with_name(trajectory.name.removesuffix(".csv") + STEPS_SUFFIX)


def is_trajectory_file(path: Path) -> bool:
    """A trajectory CSV, not the per-step file beside it."""
    return path.suffix == ".csv" and not path.name.endswith(STEPS_SUFFIX)


def write_steps_csv(path: str | Path, rows: Iterable[dict]) -> Path:
    """Write the per-step record (`EpisodeResult.step_rows`) with STEP_COLUMNS; an empty
    decision_ms is one the run did not measure (a replay), an empty prediction_trust one the
    planner keeps no record for (or a replay)."""
    path = Path(path)
    with atomic_file(path) as tmp, tmp.open("w", newline="") as handle:
        handle.write(",".join(STEP_COLUMNS) + "\n")
        for row in rows:
            handle.write(
                f"{int(row['step'])},{_format_number(row['distance_m'], 6)},{_format_number(row['explored_m2'], 4)},"
                f"{_format_number(row['explored_share'], 6)},{_format_number(row['decision_ms'], 3)},"
                f"{_format_number(row.get('prediction_trust'), 4)},{_flag(row.get('fallback'))}\n"
            )
    return path


def read_steps_csv(path: str | Path) -> dict[str, np.ndarray]:
    """Read a per-step file into one array per column (decision_ms, prediction_trust, fallback NaN
    where empty); ValueError naming the file when it is missing or its header is not STEP_COLUMNS
    (or an older one of LEGACY_STEP_COLUMNS, read with the missing columns all NaN)."""
    path = Path(path)
    if not is_file_named(path):
        raise ValueError(
            f"{path}: file not found (guide benchmark writes one per trajectory; "
            "guide replay --steps makes one from a trajectory)"
        )
    with path.open(newline="", encoding="utf-8-sig") as handle:
        rows = list(csv.reader(handle))
    header = [c.strip() for c in rows[0]] if rows else []
    if header != STEP_COLUMNS and header not in LEGACY_STEP_COLUMNS:
        raise ValueError(f"{path}: a per-step file starts with the header {','.join(STEP_COLUMNS)}")
    try:
        values = np.array(
            [[float(v) if v.strip() else np.nan for v in row] for row in rows[1:] if row], dtype=np.float64
        ).reshape(-1, len(header))
    except ValueError:
        raise ValueError(f"{path}: every row must be {len(header)} numbers ({','.join(header)})") from None
    if len(header) < len(STEP_COLUMNS):
        values = np.hstack([values, np.full((len(values), len(STEP_COLUMNS) - len(header)), np.nan)])
    if not len(values):
        raise ValueError(f"{path}: no rows (the first is the start, step 0)")
    columns = {name: values[:, k] for k, name in enumerate(STEP_COLUMNS)}
    columns["step"] = columns["step"].astype(np.int64)
    return columns


def recorded_start(trajectory: Path) -> tuple[Path, list[float]] | None:
    """(run.json, its start override) of the run that wrote `trajectory`: explore writes run.json
    beside it, benchmark one folder up (OUT/label/map.csv); None when neither records a start."""
    for record_path in (trajectory.parent / "run.json", trajectory.parent.parent / "run.json"):
        try:
            start = json.loads(record_path.read_text()).get("start")
        except (OSError, ValueError, AttributeError):
            continue
        if isinstance(start, list) and len(start) == 2:
            return record_path, start
    return None
