"""How fast a planner uncovers a map: coverage curves, the distance to a share of the free area,
the normalised area under the coverage-distance curve, and the paper's Table V efficiency.

Distance to complete is one number per episode; these read the per-step record
(`EpisodeResult.step_rows`, OUT/<label>/<map>.steps.csv) so that a benchmark folder alone is
enough to recompute every figure here.

The coverage curve of an episode is a step function: the share of the ground-truth free area
known after sensing at a waypoint holds until the next waypoint (the lidar senses only there).
After an episode ends its curve holds its last share, so episodes of different lengths average
on one axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np
import pandas as pd

from pipeline.world.trajectories import STEP_COLUMNS, read_steps_csv

COVERAGE_LEVELS = (0.5, 0.9, 0.99)  # shares of the free area whose distance is reported
PAPER_SPEED_MPS = 2.0  # the paper's simulated robot's maximum speed (Sec. V-B, Table V)
EXPLORATION_CSV = "exploration.csv"  # beside metrics.csv: one row per planner

StepRecord = Mapping[str, np.ndarray]  # read_steps_csv's columns


@dataclass(frozen=True)
class SpeedModel:
    """Exploration time in seconds: the distance driven at `speed_mps`, plus every decision's
    measured time, during which the robot waits. The paper's Table V divides by such a makespan;
    its robot drives at up to 2 m/s, so this is the time a robot at that speed would take if it
    never slowed down and never planned while driving."""

    speed_mps: float = PAPER_SPEED_MPS

    def __post_init__(self) -> None:
        if (
            isinstance(self.speed_mps, bool)
            or not isinstance(self.speed_mps, (int, float))
            or not math.isfinite(self.speed_mps)
            or self.speed_mps <= 0
        ):
            raise ValueError(f"speed_mps must be a positive number of metres per second, got {self.speed_mps!r}")

    def times(self, record: StepRecord) -> np.ndarray:
        """Seconds at each row of a per-step record (decision times the record lacks count as 0)."""
        decisions = np.nan_to_num(np.asarray(record["decision_ms"], dtype=np.float64), nan=0.0)
        return np.asarray(record["distance_m"], dtype=np.float64) / self.speed_mps + np.cumsum(decisions) / 1e3


def step_record(rows: Iterable[Mapping[str, float | None]]) -> dict[str, np.ndarray]:
    """`EpisodeResult.step_rows()` as read_steps_csv's columns (None decision times become NaN)."""
    rows = list(rows)
    record = {
        name: np.array([np.nan if row.get(name) is None else row[name] for row in rows], dtype=np.float64)
        for name in STEP_COLUMNS
    }
    record["step"] = record["step"].astype(np.int64)
    return record


def distance_to_share(record: StepRecord, share: float) -> float:
    """The distance at the first waypoint whose explored share reaches `share` (NaN: never)."""
    reached = np.nonzero(np.asarray(record["explored_share"]) >= share - 1e-12)[0]
    return float(record["distance_m"][reached[0]]) if reached.size else float("nan")


def share_at(record: StepRecord, x: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The explored share at each value of `x` along `axis` (the record's distance or time per row):
    the share of the last row at or before it, the first row's before the start."""
    index = np.searchsorted(np.asarray(axis), np.asarray(x, dtype=np.float64), side="right") - 1
    return np.asarray(record["explored_share"], dtype=np.float64)[np.clip(index, 0, None)]


def coverage_auc(record: StepRecord, horizon_m: float) -> float:
    """The mean explored share over the first `horizon_m` metres: the area under the coverage-distance
    step curve divided by the horizon, in [0, 1] (1: everything seen from the start). The last
    share holds after the episode ends."""
    distance = np.asarray(record["distance_m"], dtype=np.float64)
    share = np.asarray(record["explored_share"], dtype=np.float64)
    if not horizon_m > 0:
        return float(share[-1])
    edges = np.minimum(np.append(distance, max(horizon_m, distance[-1])), horizon_m)
    return float(np.sum(share * np.diff(edges)) / horizon_m)


def level_name(level: float) -> str:
    """0.9 -> 'distance_to_90_m'."""
    return f"distance_to_{round(level * 100):d}_m"


def episode_table(
    records: Mapping[tuple[str, str], StepRecord],
    speed: SpeedModel = SpeedModel(),
    levels: Sequence[float] = COVERAGE_LEVELS,
) -> pd.DataFrame:
    """One row per (planner, map): distance to each level, the normalised coverage AUC, and the
    Table V quantities (final explored area, distance, time, area per metre and per second).

    The AUC's horizon on a map is the longest episode among the planners given on that map, so
    AUCs compare the planners of one comparison, not across comparisons."""
    horizons: dict[str, float] = {}
    for (_, map_name), record in records.items():
        horizons[map_name] = max(horizons.get(map_name, 0.0), float(record["distance_m"][-1]))
    rows = []
    for (planner, map_name), record in sorted(records.items()):
        distance = float(record["distance_m"][-1])
        area = float(record["explored_m2"][-1])
        seconds = float(speed.times(record)[-1])
        rows.append(
            {
                "planner": planner,
                "map": map_name,
                **{level_name(level): distance_to_share(record, level) for level in levels},
                "coverage_auc": coverage_auc(record, horizons[map_name]),
                "explored_m2": area,
                "distance_m": distance,
                "time_s": seconds,
                "efficiency_m2_per_m": area / distance if distance > 0 else float("nan"),
                "efficiency_m2_per_s": area / seconds if seconds > 0 else float("nan"),
            }
        )
    return pd.DataFrame(rows)


def planner_table(
    episodes: pd.DataFrame, speed: SpeedModel = SpeedModel(), levels: Sequence[float] = COVERAGE_LEVELS
) -> pd.DataFrame:
    """Per planner (the exploration.csv rows): means over maps of `episode_table`'s columns, and per
    level how many maps reached it (`reached_90` ...); a level's mean distance is over the maps that
    reached it. Efficiencies are means of the per-map ratios, as the paper averages its runs."""
    columns = [level_name(level) for level in levels] + [
        "coverage_auc",
        "explored_m2",
        "distance_m",
        "time_s",
        "efficiency_m2_per_m",
        "efficiency_m2_per_s",
    ]
    rows = []
    for planner, group in episodes.groupby("planner", sort=True):
        row: dict[str, object] = {"planner": planner, "maps": len(group)}
        for column in columns:
            values = group[column].to_numpy(dtype=np.float64)
            row[column] = float(np.nanmean(values)) if np.isfinite(values).any() else float("nan")
        for level in levels:
            row[f"reached_{round(level * 100):d}"] = int(np.isfinite(group[level_name(level)]).sum())
        row["speed_mps"] = speed.speed_mps
        rows.append(row)
    return pd.DataFrame(rows)


def records_from_results(results: Iterable) -> dict[tuple[str, str], dict[str, np.ndarray]]:
    """{(planner label, map): per-step record} of EpisodeResults."""
    return {(result.planner, result.map_name): step_record(result.step_rows()) for result in results}


def read_step_records(out_dir: str | Path, frame: pd.DataFrame) -> dict[tuple[str, str], dict[str, np.ndarray]]:
    """The per-step records of every (planner, map) row of a benchmark's metrics (ValueError naming a
    missing or malformed file: a benchmark folder written before per-step files existed must be rerun)."""
    out_dir = Path(out_dir)
    return {
        (str(planner), str(map_name)): read_steps_csv(out_dir / str(planner) / f"{map_name}.steps.csv")
        for planner, map_name in frame[["planner", "map"]].itertuples(index=False)
    }


def mean_curve(
    records: Sequence[StepRecord], grid: np.ndarray, speed: SpeedModel | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(mean, standard deviation) over episodes of the explored share at each `grid` value: metres
    of distance, or seconds of time when a speed model is given."""
    shares = np.stack(
        [
            share_at(record, grid, speed.times(record) if speed is not None else record["distance_m"])
            for record in records
        ]
    )
    return shares.mean(axis=0), shares.std(axis=0)
