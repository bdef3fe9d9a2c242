"""DAgger's episodes (ours): a driver explores training mazes and a teacher labels every state.

In round 0 the teacher drives (`student=None`); in each later round the diffusion policy of the
round before drives, as the paper's receding-horizon planner (`guide:mode=policy`), and the
teacher labels the states the policy itself reaches, so that the aggregated data covers the
policy's own mistakes (Ross et al., 2011). The shards have the expert shards' format, with
the teacher's label as each step's `future_waypoints`, so `episode_observations` replays them into
graph observations unchanged; `driver_agrees` adds, per step, whether the driver's move was the
teacher's first step.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from pipeline.data.collect import episode_shard_arrays, random_open_start, record_episode
from pipeline.data.shards import ShardJob, shard_path, write_shard
from pipeline.data.teacher_labels import TeacherLabelledDriver
from pipeline.planners import make_planner
from pipeline.world.maps import load_map
from pipeline.world.protocol import Protocol

STUDENT = "guide"  # the policy drives as the paper's planner: guide in mode policy


@dataclass(frozen=True)
class DaggerConfig:
    """One round's collection: which mazes, who drives, who labels."""

    maps: tuple[str, ...]
    episodes_per_shard: int
    teacher: str = "greedy_utility"  # gated greedy: deterministic given the belief, its target a node the policy sees
    teacher_options: dict[str, Any] = field(default_factory=lambda: {"sliver_gate": True})
    student: str | None = None  # the policy export that drives; None: the teacher drives
    horizon: int = 8  # T_p labelled waypoints per step
    seed: int = 0
    round: int = 0
    protocol: Protocol = Protocol()
    random_starts: bool = True  # each episode from a random open cell, as the expert's


def labelled_driver(config: DaggerConfig) -> TeacherLabelledDriver:
    teacher = make_planner(config.teacher, **config.teacher_options)
    driver = None if config.student is None else make_planner(STUDENT, mode="policy", policy_file=config.student)
    return TeacherLabelledDriver(teacher, config.horizon, driver)


def step_labels(planner: TeacherLabelledDriver, trajectory: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(steps, T_p, 2) labels and (steps,) agreement, one per trajectory row; a final row the
    teacher was not asked about (the map was done) is labelled with a stay and does not agree."""
    steps = len(trajectory)
    labels = np.repeat(trajectory[:, None, :], planner.horizon, axis=1).astype(np.float32)
    agrees = np.zeros(steps, dtype=bool)
    asked = min(steps, len(planner.labels))
    if asked:
        labels[:asked] = np.stack(planner.labels[:asked])
        agrees[:asked] = planner.agrees[:asked]
    return labels, agrees


def collect_dagger_shard(job: ShardJob) -> dict[str, Any]:
    """Write `episodes_per_shard` labelled episodes as one shard; return its counts."""
    config: DaggerConfig = job.params["config"]
    rng = np.random.default_rng([config.seed, config.round, job.index])
    planner = labelled_driver(config)
    ground_truths, names, records, agreements = [], [], [], []
    for _ in range(config.episodes_per_shard):
        map_path = str(rng.choice(config.maps))
        ground_truth = load_map(map_path, cell_size=config.protocol.cell_size)
        if config.random_starts:
            ground_truth = random_open_start(ground_truth, rng)
        record = record_episode(ground_truth, planner, config.protocol, seed=int(rng.integers(1 << 31)))
        record["targets"], agrees = step_labels(planner, record["trajectory"])
        records.append(record)
        agreements.append(agrees)
        ground_truths.append(ground_truth)
        names.append(Path(map_path).name)
    arrays = episode_shard_arrays(ground_truths, names, records)
    arrays["driver_agrees"] = np.concatenate(agreements)
    moves = int(sum(len(r["trajectory"]) - 1 for r in records))  # decisions that moved the robot
    arrays["summary_moves"] = np.array(moves)
    arrays["summary_agreements"] = np.array(int(sum(a[:-1].sum() for a in agreements)))
    path = shard_path(job.out_dir, job.index)
    write_shard(path, arrays)
    return {
        "episodes": len(records),
        "steps": int(arrays["summary_steps"]),
        "complete": int(arrays["summary_complete"]),
        "moves": moves,
        "agreements": int(arrays["summary_agreements"]),
        "bytes": path.stat().st_size,
    }
