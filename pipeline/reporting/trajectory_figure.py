"""The trajectory figure of reports/: each planner's route on the first test mazes, side by side."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np
import pandas as pd

from pipeline.reporting.panels import render_comparison
from pipeline.reporting.render import PANEL_GAP_RGB, save_png
from pipeline.reporting.tables import check_metrics
from pipeline.world.maps import load_map
from pipeline.world.protocol import Protocol
from pipeline.world.trajectories import read_trajectory_csv

FIGURE_MAPS = 2


def trajectory_figure(
    map_paths: Sequence[str | Path],
    frame: pd.DataFrame,
    out_dir: str | Path,
    planners: Sequence[str],
    path: str | Path,
    protocol: Protocol | None = None,
    max_maps: int = FIGURE_MAPS,
) -> Path:
    """A PNG grid: one row per map (the first `max_maps` with trajectories), one panel per
    planner of `planners` that has a trajectory OUT/planner/map.csv and a metrics row.

    Raises ValueError when no listed planner has a trajectory on any of the maps.
    """
    protocol = protocol or Protocol()
    out_dir = Path(out_dir)
    frame = check_metrics(frame)
    rows: list[np.ndarray] = []
    for map_path in map_paths:
        if len(rows) >= max_maps:
            break
        ground_truth = load_map(map_path, cell_size=protocol.cell_size)
        on_map = frame[frame["map"].astype(str) == ground_truth.name]
        panels = []
        for planner in planners:
            match = on_map[on_map["planner"] == planner]
            csv_path = out_dir / planner / f"{ground_truth.name}.csv"
            if len(match) and csv_path.is_file():
                panels.append((planner, read_trajectory_csv(csv_path), float(match["distance_m"].iloc[0])))
        if panels:
            rows.append(render_comparison(ground_truth, panels, title=f"map {ground_truth.name}"))
    if not rows:
        raise ValueError(
            f"no trajectories of {list(planners)} under {out_dir} for maps {[Path(p).stem for p in map_paths]}"
        )
    width = max(r.shape[1] for r in rows)
    gap = 8
    blocks = []
    for i, image in enumerate(rows):
        if image.shape[1] < width:
            pad = np.empty((image.shape[0], width - image.shape[1], 3), dtype=np.uint8)
            pad[:] = PANEL_GAP_RGB
            image = np.concatenate([image, pad], axis=1)
        if i:
            spacer = np.empty((gap, width, 3), dtype=np.uint8)
            spacer[:] = PANEL_GAP_RGB
            blocks.append(spacer)
        blocks.append(image)
    return save_png(np.ascontiguousarray(np.concatenate(blocks, axis=0)), path)
