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
from typing import Any

import pandas as pd

from pipeline.common.params import complete_section, load_params
from pipeline.common.paths import DATA, REPORTS
from pipeline.common.settings import Fields, ListOf, Maybe, Real, Text, Whole, check_stage, fraction, keys_of
from pipeline.prediction.node_predictor import NodePredictorConfig
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.table1 import log_run, predictor_folder, table1_graph_config
from pipeline.world.protocol import Protocol

TEST_MAZES = DATA.mazes_test
OUT_DIR = REPORTS.predictor
SETTINGS = Fields({
    "steps": ListOf(Whole(0, note="exploration steps")),
    "threshold": fraction("tau of V_u"),
    "min_component": Whole(0, note="0 or 1: keep every predicted node"),
    "keep_share": Real(0.0, 1.0, low_open=True, note="share of scored regions"),
    "sweep_thresholds": Maybe(ListOf(fraction(), min_length=0), "no sweep"),
    "checkpoint": Maybe(Text(note="an inpainter export"), "models/inpainter/inpainter.pt"),
    "compare_checkpoint": Maybe(Text(note="an inpainter export"), "no comparison"),
})
SECTION_KEYS = set(keys_of(SETTINGS))


def read_params(params_path: str | Path) -> tuple[dict[str, Any], Protocol]:
    params = load_params(params_path)
    section = complete_section(params, "eval_predictor", params_path, SECTION_KEYS)
    sweep = section["sweep_thresholds"]
    if sweep is None:
        section["sweep_thresholds"] = []
    elif not isinstance(sweep, list) or any(isinstance(t, bool) or not isinstance(t, (int, float)) or not 0 <= t <= 1
                                            for t in sweep):
        raise ValueError(f"{params_path}: eval_predictor.sweep_thresholds must be a list of numbers in [0, 1], got {sweep!r}")
    if not section["steps"]:
        raise ValueError(f"{params_path}: eval_predictor.steps must list at least one step")
    return section, Protocol.from_dict(params.get("protocol") or {})


def main(params_path: str = "params.yaml") -> pd.DataFrame:
    check_stage(params_path, "eval_predictor", SETTINGS)
    section, protocol = read_params(params_path)
    config = NodePredictorConfig(threshold=float(section["threshold"]), min_component=int(section["min_component"]))
    graph_config = table1_graph_config(float(section["keep_share"]))
    frame = predictor_folder(TEST_MAZES, OUT_DIR, section["checkpoint"], section["compare_checkpoint"], section["steps"],
                             config, protocol, graph_config=graph_config, sweep_thresholds=section["sweep_thresholds"])
    log_run(frame, OUT_DIR, section, protocol, str(TEST_MAZES))
    print((OUT_DIR / "table1.md").read_text())
    return frame


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
