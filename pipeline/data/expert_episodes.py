"""Stage II data: expert episodes as raw per-step state, as `collect_expert_shard` writes them.

Per step: the cells the scan revealed (a compact, exact diff of the belief), the robot's
position and the expert's next T_p waypoints, plus the ground-truth grid, so that graph
observations can be rebuilt later with any node predictor.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from pipeline.data.shards import read_shard


@dataclass
class ExpertEpisode:
    """One stored expert episode, with its beliefs rebuilt on demand."""

    map_name: str
    ground_truth: np.ndarray  # bool (rows, cols)
    start_cell: tuple[int, int]
    positions: np.ndarray  # (steps, 2)
    future_waypoints: np.ndarray  # (steps, T_p, 2)
    change_index: list[np.ndarray]
    change_value: list[np.ndarray]

    def beliefs(self):
        """Yield the belief grid before each decision (after the scan at step t)."""
        grid = np.full(self.ground_truth.shape, 128, dtype=np.uint8)
        flat = grid.reshape(-1)
        for index, value in zip(self.change_index, self.change_value):
            flat[index] = value
            yield grid


def load_expert_episodes(path: str | Path) -> list[ExpertEpisode]:
    """Unpack one Stage II shard into episodes."""
    d = read_shard(path)
    episodes = []
    bit_offsets = np.concatenate([[0], np.cumsum(d["ground_truth_bit_lengths"])])
    step_offsets = np.concatenate([[0], np.cumsum(d["step_counts"])])
    change_offsets = np.concatenate([[0], np.cumsum(d["change_counts"])])
    for e, name in enumerate(d["map_names"]):
        rows, cols = (int(v) for v in d["map_shapes"][e])
        bits = d["ground_truth_bits"][bit_offsets[e] : bit_offsets[e + 1]]
        grid = np.unpackbits(bits, count=rows * cols).astype(bool).reshape(rows, cols)
        s0, s1 = step_offsets[e], step_offsets[e + 1]
        changes_i, changes_v = [], []
        for step in range(s0, s1):
            c0, c1 = change_offsets[step], change_offsets[step + 1]
            changes_i.append(d["change_index"][c0:c1])
            changes_v.append(d["change_value"][c0:c1])
        episodes.append(
            ExpertEpisode(
                map_name=str(name),
                ground_truth=grid,
                start_cell=(int(d["start_cells"][e][0]), int(d["start_cells"][e][1])),
                positions=d["positions"][s0:s1],
                future_waypoints=d["future_waypoints"][s0:s1],
                change_index=changes_i,
                change_value=changes_v,
            )
        )
    return episodes
