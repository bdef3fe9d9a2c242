"""DVC stage: precision of structural inference on the test mazes (paper Table I and Fig. 3).

Reads only the `eval_predictor` section (steps, threshold, min_component, keep_share,
sweep_thresholds, checkpoint, compare_checkpoint) and the shared `protocol` section of params.yaml. Explores each
test maze with nearest_frontier, runs the Global Node Predictor with the trained inpainter at
each step and region evaluation, and writes reports/predictor/precision.csv (with
precision_detail.csv: V_u split into predictions and centroids), reports/predictor/table1.md
(ours beside the paper's, and the precision at each tau of `sweep_thresholds`),
reports/predictor/precision_by_threshold.csv, threshold_sweep.png and fig3.png; with
`compare_checkpoint` (by default the shipped inpainter, trained at the paper profile's scale)
Table I again with that network on the same explorations, reports/predictor/precision_compare.csv
and a section of table1.md, so a CPU-sized profile still shows where a larger model lands.
Logs one MLflow run in experiment "table1".
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from pipeline.common.config import Section, fraction, list_of, maybe, real, text, whole
from pipeline.common.paths import DATA, REPORTS
from pipeline.prediction.node_predictor import NodePredictorConfig
from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.table1 import log_run, predictor_folder, table1_graph_config
from pipeline.world.protocol import Protocol

TEST_MAZES = DATA.mazes_test
OUT_DIR = REPORTS.predictor


class Settings(Section):
    """The `eval_predictor` section of params.yaml."""

    steps: list_of(whole(0, note="exploration steps"))
    threshold: fraction("tau of V_u")
    min_component: whole(0, note="0 or 1: keep every predicted node")
    keep_share: real(0.0, 1.0, low_open=True, note="share of scored regions")
    sweep_thresholds: maybe(list_of(fraction(), min_length=0), "no sweep")
    checkpoint: maybe(text(note="an inpainter export"), "models/inpainter/inpainter.pt")
    compare_checkpoint: maybe(text(note="an inpainter export"), "no comparison")


def read_params(params_path: str | Path) -> tuple[Settings, Protocol]:
    """The settings and the protocol."""
    return read_stage(params_path, "eval_predictor", Settings), read_protocol(params_path)


def main(params_path: str = "params.yaml") -> pd.DataFrame:
    settings, protocol = read_params(params_path)
    frame = predictor_folder(
        TEST_MAZES,
        OUT_DIR,
        settings.checkpoint,
        settings.compare_checkpoint,
        settings.steps,
        NodePredictorConfig(threshold=settings.threshold, min_component=settings.min_component),
        protocol,
        graph_config=table1_graph_config(settings.keep_share),
        sweep_thresholds=settings.sweep_thresholds or [],  # null: no sweep
    )
    log_run(frame, OUT_DIR, settings.as_written(), protocol, str(TEST_MAZES))
    print((OUT_DIR / "table1.md").read_text())
    return frame


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
