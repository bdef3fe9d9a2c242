"""DVC stage: benchmark the configured planners on the test mazes.

Reads the `benchmark` section (planners, seed, workers, speed_mps) and the shared `protocol`
section of params.yaml. Writes docs/protocol.md's outputs under reports/benchmark/, the
DVC metrics file reports/benchmark.json, a PNG bar chart, the coverage curves and a side-by-side
trajectory figure, and one MLflow run per planner.
"""

from __future__ import annotations

from pathlib import Path

from pipeline.common.params import complete_section, load_params
from pipeline.common.settings import Fields, ListOf, Maybe, Satisfies, Whole, check_stage, keys_of, positive
from pipeline.planners.specs import resolve_planner_specs
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.benchmark import benchmark_test_mazes
from pipeline.world.protocol import Protocol

# A planner entry as on the command line, checked by the benchmark's own parser and the registry.
PLANNER_SPEC = Satisfies(lambda spec: resolve_planner_specs([spec]),
                         "a planner spec: a registered planner's name or label=name:option=value,...")
SETTINGS = Fields({
    "planners": ListOf(PLANNER_SPEC),
    "seed": Whole(0),
    "workers": Maybe(Whole(1), "all cores"),
    "speed_mps": positive("metres per second"),
})
KEYS = keys_of(SETTINGS)


def read_params(params_path: str | Path) -> tuple[dict, Protocol]:
    params = load_params(params_path)
    section = complete_section(params, "benchmark", params_path, KEYS)
    if not isinstance(section["planners"], list) or not section["planners"]:
        raise ValueError(f"{params_path}: the 'benchmark' section needs a 'planners' list")
    return section, Protocol.from_dict(params.get("protocol") or {})


def main(params_path: str = "params.yaml") -> None:
    check_stage(params_path, "benchmark", SETTINGS)
    section, protocol = read_params(params_path)
    benchmark_test_mazes(section, protocol)


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
