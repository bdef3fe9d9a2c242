"""DVC stage: benchmark the configured planners on the test mazes.

Reads the `benchmark` section (planners, seed, workers, speed_mps; robots, team_planners,
comm_range_m for the teams) and the shared `protocol` section of params.yaml. Writes
docs/protocol.md's outputs under reports/benchmark/, the DVC metrics file reports/benchmark.json,
a PNG bar chart, the coverage curves and a side-by-side trajectory figure, and one MLflow run per
planner; then the team runs (docs/teams.md) under reports/teams/ with reports/teams.json, and one
MLflow run per team planner and robot count.
"""

from __future__ import annotations

from pipeline.common.config import Section, list_of, maybe, positive, satisfies, whole
from pipeline.evaluation.team_benchmark import resolve_team_specs
from pipeline.planners.specs import resolve_planner_specs
from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.benchmark import benchmark_test_mazes

# A planner entry as on the command line, checked by the benchmark's own parser and the registry.
PLANNER_SPEC = satisfies(
    lambda spec: resolve_planner_specs([spec]),
    "a planner spec: a registered planner's name or label=name:option=value,...",
)
# A team planner entry: a coordinated team name, uncoordinated_<name>, or a single planner's name.
TEAM_PLANNER_SPEC = satisfies(
    lambda spec: resolve_team_specs([spec]),
    "a team planner spec: a planner's name (its coordinated team version where there is "
    "one) or uncoordinated_<name>, with label=...:option=value,... as for planners",
)


class Settings(Section):
    """The `benchmark` section of params.yaml."""

    planners: list_of(PLANNER_SPEC)
    seed: whole(0)
    workers: maybe(whole(1), "all cores")
    speed_mps: positive("metres per second")
    robots: list_of(whole(1, 8), min_length=0) = []
    team_planners: list_of(TEAM_PLANNER_SPEC, min_length=0) = []
    comm_range_m: maybe(positive("metres"), "one shared belief") = None


def main(params_path: str = "params.yaml") -> None:
    benchmark_test_mazes(read_stage(params_path, "benchmark", Settings), read_protocol(params_path))


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
