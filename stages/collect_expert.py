"""DVC stage: Stage II expert episodes on training mazes, as raw per-step state.

Reads the `collect_expert` section (and the shared `protocol`); writes shards and a
manifest to data/expert/ and a picture of one stored episode to
reports/expert_episode.png (rebuilt from the shard, so it also checks the round trip).
"""

from __future__ import annotations

from pipeline.common.params import complete_section, load_params
from pipeline.common.settings import Fields, Flag, Satisfies, Text, Whole, check_stage, keys_of
from pipeline.planners import planner_config
from pipeline.planners.registry import accepted_options, make_config
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.collect_expert import collect_expert
from pipeline.world.protocol import Protocol

def check_options(options: object) -> None:
    """A mapping of option names to values (which the planner takes is checked in `main`)."""
    if not isinstance(options, dict):
        raise TypeError("not a mapping")


SETTINGS = Fields({
    "seed": Whole(0),
    "episodes": Whole(1),
    "episodes_per_shard": Whole(1),
    "planner": Satisfies(planner_config, "a registered planner name"),
    "planner_options": Satisfies(check_options, "a mapping of the planner's options"),
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
    options = section["planner_options"]
    accepted = accepted_options(section["planner"], options)
    for key in options:  # an option the planner does not take fails here, by its key, not in the first worker
        if key not in accepted:
            raise ValueError(f"{params_path}: collect_expert.planner_options.{key}: {section['planner']} has no such "
                             f"option; it accepts: {', '.join(accepted)}")
    try:
        make_config(section["planner"], **options)
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
