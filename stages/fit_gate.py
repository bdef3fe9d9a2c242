"""DVC stage: fit the sliver gate on greedy episodes in the training mazes.

Reads only the `fit_gate` section (maps, holdout_maps, offices, office_holdout, hidden,
fit_samples, min_gain, wall_margin, threshold, workers) and the shared `protocol` section of params.yaml.
Runs `greedy_utility` on the first `maps` training mazes and the first `offices` office
floors, labels every reachable target at every decision by the cells its scan would truly
reveal, fits the gate (`pipeline.planners.extensions.sliver_gate`; `hidden` layers, none: logistic) on all but
the last `holdout_maps` mazes and `office_holdout` floors and measures it on those, per family. Writes models/sliver_gate/sliver_gate.json,
reports/sliver_gate.json (sample counts, held-out ROC AUC of the gate and of each count
alone, held-out accuracy at the gate's threshold) and reports/sliver_gate.png (held-out ROC
curves). Logs one MLflow run in experiment "sliver_gate".
"""

from __future__ import annotations

import json
from typing import Any

from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.fit_gate import Settings, fit_gate


def main(params_path: str = "params.yaml") -> dict[str, Any]:
    """Fit, measure and write the gate; returns the metrics written to reports/sliver_gate.json."""
    metrics = fit_gate(read_stage(params_path, "fit_gate", Settings), read_protocol(params_path))
    print(json.dumps(metrics, indent=2))
    return metrics


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
