"""DVC stage: Stage I (observed, ground-truth) node-image pairs from rollouts in training mazes.

Reads the `collect_pairs` section (and the shared `protocol`); writes shards and a
manifest to data/pairs/ and a picture of a few pairs to reports/pairs_preview.png.
"""

from __future__ import annotations

from pipeline.common.params import complete_section, load_params
from pipeline.common.settings import Fields, ListOf, Pair, Satisfies, Text, Whole, check_stage, keys_of
from pipeline.planners import planner_config
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.collect_pairs import collect_pairs
from pipeline.world.protocol import Protocol

SETTINGS = Fields({
    "seed": Whole(0),
    "pairs": Whole(1),
    "pairs_per_shard": Whole(1),
    "planners": ListOf(Satisfies(planner_config, "a registered planner name")),  # each rollout builds one by name
    "snapshot_every": Whole(1, note="steps"),
    "stop_steps": Pair(Whole(1, note="steps")),
    "workers": Whole(0, note="0 or 1: in this process"),
    "backend": Text(("process", "ray")),
})
KEYS = keys_of(SETTINGS)


def main(params_path: str = "params.yaml", backend: str | None = None) -> dict:
    check_stage(params_path, "collect_pairs", SETTINGS)
    params = load_params(params_path)
    section = complete_section(params, "collect_pairs", params_path, KEYS)
    protocol = Protocol.from_dict(params.get("protocol") or {})
    return collect_pairs(section, protocol, backend)


if __name__ == "__main__":
    parser = stage_arguments(__doc__)
    parser.add_argument("--backend", choices=["process", "ray"], default=None,
                        help="process (default) or ray (pip install '.[ray]')")
    args = parser.parse_args()
    run_stage_main(main, args.params, args.backend)
