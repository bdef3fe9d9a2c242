"""DVC stage: replay the Stage II expert episodes into graph observations with the frozen predictor.

Reads only the `build_observations` section of params.yaml (and the shared `protocol`).
For every stored expert step it rebuilds the belief, runs the trained inpainter once
(models/inpainter/inpainter.pt unless `inpainter` names another export; graph nodes at
`threshold`, the utility boost's count at `count_threshold`) and writes two
observation sets: data/observations/guide.npz (region-evaluated global graph) and
data/observations/dare.npz (observed graph only), plus reports/observations_summary.json.
Its own stage, so retraining the planner never re-runs the predictor.
"""

from __future__ import annotations

from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.build_observations import Settings, build_observations


def main(params_path: str = "params.yaml") -> dict:
    return build_observations(read_stage(params_path, "build_observations", Settings), read_protocol(params_path))


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
