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

from pipeline.common.params import complete_section, load_params
from pipeline.common.settings import Fields, Maybe, Text, Whole, check_stage, fraction, keys_of
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.build_observations import build_observations
from pipeline.world.protocol import Protocol

SETTINGS = Fields({
    "max_nodes": Whole(1),
    "max_neighbors": Whole(1),
    "threshold": fraction("tau of the graph's predicted nodes"),
    "count_threshold": fraction("tau of the nodes the utility boost counts"),
    "min_component": Whole(0, note="0 or 1: keep every predicted node"),
    "inpainter": Maybe(Text(note="an inpainter export"), "models/inpainter/inpainter.pt"),
    "workers": Whole(0, note="0 or 1: in this process"),
})
KEYS = keys_of(SETTINGS)


def main(params_path: str = "params.yaml") -> dict:
    check_stage(params_path, "build_observations", SETTINGS)
    params = load_params(params_path)
    section = complete_section(params, "build_observations", params_path, KEYS)
    protocol = Protocol.from_dict(params.get("protocol") or {})
    return build_observations(section, protocol)


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
