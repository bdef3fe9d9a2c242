"""DVC stage: fit the sliver gate on greedy episodes in the training mazes.

Reads only the `fit_gate` section (maps, holdout_maps, offices, office_holdout, hidden,
min_gain, wall_margin, threshold, workers) and the shared `protocol` section of params.yaml.
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
from pathlib import Path
from typing import Any

from pipeline.common.params import complete_section, load_params
from pipeline.common.settings import Fields, ListOf, Whole, check_stage, fraction, keys_of
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.fit_gate import fit_gate
from pipeline.world.protocol import Protocol

SETTINGS = Fields({
    "maps": Whole(1),
    "holdout_maps": Whole(0),
    "offices": Whole(0),
    "office_holdout": Whole(0),
    "hidden": ListOf(Whole(1), min_length=0, description="a list of layer widths (whole numbers >= 1; []: logistic)"),
    "min_gain": Whole(0, note="cells"),
    "wall_margin": Whole(0, note="cells"),
    "threshold": fraction("P(big)"),
    "workers": Whole(1),
})
KEYS = keys_of(SETTINGS)


def read_params(params_path: str | Path) -> tuple[dict[str, Any], Protocol]:
    params = load_params(params_path)
    section = complete_section(params, "fit_gate", params_path, KEYS)
    for key in ("maps", "holdout_maps", "offices", "office_holdout", "min_gain", "wall_margin", "workers"):
        value = section[key]
        if isinstance(value, bool) or not isinstance(value, int) or value < (1 if key in ("maps", "workers") else 0):
            raise ValueError(f"{params_path}: fit_gate.{key} must be a whole number, got {value!r}")
    if not section["holdout_maps"] < section["maps"]:
        raise ValueError(f"{params_path}: fit_gate.holdout_maps must be below fit_gate.maps")
    if section["offices"] and not section["office_holdout"] < section["offices"]:
        raise ValueError(f"{params_path}: fit_gate.office_holdout must be below fit_gate.offices")
    hidden = section["hidden"]
    if not isinstance(hidden, list) or not all(isinstance(h, int) and not isinstance(h, bool) and h > 0 for h in hidden):
        raise ValueError(f"{params_path}: fit_gate.hidden must be a list of layer widths (whole numbers > 0), got {hidden!r}")
    return section, Protocol.from_dict(params.get("protocol") or {})


def main(params_path: str = "params.yaml") -> dict[str, Any]:
    """Fit, measure and write the gate; returns the metrics written to reports/sliver_gate.json."""
    check_stage(params_path, "fit_gate", SETTINGS)
    section, protocol = read_params(params_path)
    metrics = fit_gate(section, protocol)
    print(json.dumps(metrics, indent=2))
    return metrics


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
