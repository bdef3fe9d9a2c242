"""Stage I data: (observed, ground-truth) node-image pairs, as `collect_pairs_shard` writes them.

A shard holds, per image size S of `PAD_SIZES`, arrays `observed_S`, `target_S` and `valid_S`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from pipeline.prediction.node_image import PAD_SIZES


def load_pairs(shard_files: list[Path]) -> dict[int, dict[str, np.ndarray]]:
    """All pairs of a data set grouped by image size: {size: {observed, target, valid}}."""
    grouped: dict[int, dict[str, list[np.ndarray]]] = {}
    for path in shard_files:
        with np.load(path, allow_pickle=False) as data:
            for size in PAD_SIZES:
                if f"observed_{size}" in data.files:
                    group = grouped.setdefault(size, {"observed": [], "target": [], "valid": []})
                    for key in group:
                        group[key].append(data[f"{key}_{size}"])
    return {size: {k: np.concatenate(v) for k, v in group.items()} for size, group in grouped.items()}
