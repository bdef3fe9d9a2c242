"""DVC stage: the paper's Tables I-IV from our outputs, one report, one figure, MLflow runs.

Reads only the `report` section and the shared `protocol` section of params.yaml:

- k_values, k_planners, k_option, k_maps: the denoising-steps sweep (Table IV). Each
  planner of k_planners runs on the first k_maps test mazes once per K, as the variant
  f"{planner}_k{K}={planner}:{k_option}={K}", into reports/denoising_steps/.
- ablation_planners: the rows of Table III (a planner missing from the benchmark shows "not run").
- figure_planners: the panels of reports/trajectories.png (those the benchmark ran).
- workers, seed: for the sweep.

Reads reports/benchmark/metrics.csv (the benchmark stage, Tables II and III) and, when it
exists, reports/predictor/precision_detail.csv or precision.csv (the eval_predictor stage, Table I;
with precision_compare.csv, another inpainter's rows beside it). Writes
reports/tables/table{1,2,3,4}.md, reports/report.md, reports/report.json (DVC metrics)
and reports/trajectories.png, and logs one MLflow experiment per table.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from pipeline.common.params import complete_section, load_params
from pipeline.common.settings import Fields, ListOf, Maybe, Satisfies, Text, Whole, check_stage, keys_of
from pipeline.planners import planner_config
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.report import write_report
from pipeline.world.protocol import Protocol

LABEL = Text(note="a planner's label in the benchmark")  # a label absent from the benchmark shows as "not run"
SETTINGS = Fields({
    "k_values": ListOf(Whole(1), min_length=0),  # [] (or no k_planners): no sweep, no Table IV
    "k_planners": ListOf(Satisfies(planner_config, "a registered planner name"), min_length=0),
    "k_option": Text(identifier=True, note="a planner option name"),
    "k_maps": Whole(1),
    "ablation_planners": ListOf(LABEL),
    "figure_planners": ListOf(LABEL),
    "workers": Maybe(Whole(1), "all cores"),
    "seed": Whole(0),
})
KEYS = keys_of(SETTINGS)


def read_params(params_path: str | Path) -> tuple[dict[str, Any], Protocol]:
    """The `report` section (every key named, unknown keys refused) and the protocol."""
    params = load_params(params_path)
    section = complete_section(params, "report", params_path, KEYS)
    for key in ("k_values", "k_planners", "ablation_planners", "figure_planners"):
        if not isinstance(section[key], list):
            raise ValueError(f"{params_path}: report.{key} must be a list")
    section["k_values"] = [int(k) for k in section["k_values"]]
    section["k_maps"] = int(section["k_maps"])
    if section["k_maps"] < 1:
        raise ValueError(f"{params_path}: report.k_maps must be at least 1")
    if not str(section["k_option"]).isidentifier():
        raise ValueError(f"{params_path}: report.k_option must be a planner option name, got {section['k_option']!r}")
    return section, Protocol.from_dict(params.get("protocol") or {})


def main(params_path: str = "params.yaml") -> dict[str, Any]:
    check_stage(params_path, "report", SETTINGS)
    section, protocol = read_params(params_path)
    return write_report(section, protocol)


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
