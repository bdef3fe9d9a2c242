"""DVC stage: benchmark the configured planners on the test mazes.

Reads the `benchmark` section (planners, seed, workers, speed_mps; robots, team_planners,
comm_range_m for the teams) and the shared `protocol` section of params.yaml. Writes
docs/protocol.md's outputs under reports/benchmark/, the DVC metrics file reports/benchmark.json,
a PNG bar chart, the coverage curves and a side-by-side trajectory figure, and one MLflow run per
planner; then the team runs (docs/teams.md) under reports/teams/ with reports/teams.json, and one
MLflow run per team planner and robot count.
"""

from __future__ import annotations

from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.benchmark import Settings, benchmark_test_mazes


def main(params_path: str = "params.yaml") -> None:
    benchmark_test_mazes(read_stage(params_path, "benchmark", Settings), read_protocol(params_path))


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
