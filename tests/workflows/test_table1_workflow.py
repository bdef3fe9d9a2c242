"""The eval_predictor stage's folder, reports/predictor/: replaced as a whole, or left as it was."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from pipeline.evaluation.predictor_eval import all_free_inpaint
from pipeline.prediction.node_predictor import NodePredictorConfig
from pipeline.workflows import table1
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.protocol import Protocol


def files(folder: Path) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_the_predictor_folder_is_replaced_as_a_whole_or_not_at_all(tmp_path, monkeypatch):
    maps = tmp_path / "mazes"
    write_maze_png(
        generate_maze(MazeConfig(side_m=(50.0, 50.0)), np.random.default_rng([31, 0])), maps / "maze_0000.png"
    )
    monkeypatch.setattr(table1, "load_inpaint_fn", lambda checkpoint=None: all_free_inpaint)
    out = tmp_path / "reports/predictor"
    out.mkdir(parents=True)
    (out / "old.txt").write_text("an earlier run's file")

    def stage(compare_checkpoint):
        return table1.predictor_folder(
            maps,
            out,
            None,
            compare_checkpoint,
            (3,),
            NodePredictorConfig(threshold=0.5),
            Protocol(),
            graph_config=table1.table1_graph_config(0.5),
            sweep_thresholds=(0.5,),
        )

    frame = stage(None)
    first = files(out)
    assert set(first) == {
        "precision.csv",
        "precision_detail.csv",
        "precision_by_threshold.csv",
        "threshold_sweep.png",
        "table1.md",
        "fig3.png",
        "precision_compare.csv",
    }  # old.txt went with the old folder
    assert len(frame) == 1
    # compare_with fails after run has written every file of the new folder: the old one stays.
    with pytest.raises(FileNotFoundError, match="gone.pt"):
        stage(str(tmp_path / "gone.pt"))
    assert files(out) == first
    assert sorted(p.name for p in out.parent.iterdir()) == ["predictor"]
