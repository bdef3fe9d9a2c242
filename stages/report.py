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

from typing import Any

from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.report import Settings, write_report


def main(params_path: str = "params.yaml") -> dict[str, Any]:
    return write_report(read_stage(params_path, "report", Settings), read_protocol(params_path))


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
