"""DVC stage: Stage II expert episodes on training mazes, as raw per-step state.

Reads the `collect_expert` section (and the shared `protocol`); writes shards and a
manifest to data/expert/ and a picture of one stored episode to
reports/expert_episode.png (rebuilt from the shard, so it also checks the round trip).
"""

from __future__ import annotations

from pipeline.common.params import complete_section, load_params
from pipeline.common.settings import Fields, Flag, Satisfies, Text, Whole, check_stage, keys_of
from pipeline.planners import planner_config
from pipeline.planners.registry import make_config
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.collect_expert import collect_expert
from pipeline.world.protocol import Protocol

SETTINGS = Fields({
    "seed": Whole(0),
    "episodes": Whole(1),
    "episodes_per_shard": Whole(1),
    "planner": Satisfies(planner_config, "a registered planner name"),
    "planner_options": Satisfies(lambda value: isinstance(value, dict), "a mapping of the planner's options"),
    "horizon": Whole(1, note="future waypoints per step"),
    "random_starts": Flag(),
    "workers": Whole(0, note="0 or 1: in this process"),
    "backend": Text(("process", "ray")),
})
KEYS = keys_of(SETTINGS)


def main(params_path: str = "params.yaml", backend: str | None = None) -> dict:
    check_stage(params_path, "collect_expert", SETTINGS)
    params = load_params(params_path)
    section = complete_section(params, "collect_expert", params_path, KEYS)
    try:  # an option the planner does not take fails here, not in the first worker
        make_config(section["planner"], **(section.get("planner_options") or {}))
    except ValueError as error:
        raise ValueError(f"{params_path}: collect_expert.planner_options: {error}") from None
    protocol = Protocol.from_dict(params.get("protocol") or {})
    return collect_expert(section, protocol, backend)


if __name__ == "__main__":
    parser = stage_arguments(__doc__)
    parser.add_argument("--backend", choices=["process", "ray"], default=None,
                        help="process (default) or ray (pip install '.[ray]')")
    args = parser.parse_args()
    run_stage_main(main, args.params, args.backend)
