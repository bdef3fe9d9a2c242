"""DVC stage: Stage II expert episodes on training mazes, as raw per-step state.

Reads the `collect_expert` section (and the shared `protocol`); writes shards and a
manifest to data/expert/ and a picture of one stored episode to
reports/expert_episode.png (rebuilt from the shard, so it also checks the round trip).
"""

from __future__ import annotations

from typing import Any

from pydantic import ValidationInfo, field_validator
from pydantic_core import PydanticCustomError

from pipeline.common.config import Section, flag, satisfies, whole
from pipeline.planners import planner_config
from pipeline.planners.registry import accepted_options, make_config
from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.collect_expert import collect_expert


class Settings(Section):
    """The `collect_expert` section of params.yaml."""

    seed: whole(0)
    episodes: whole(1)
    episodes_per_shard: whole(1)
    planner: satisfies(planner_config, "a registered planner name", str)
    planner_options: dict[str, Any]
    horizon: whole(1, note="future waypoints per step")
    random_starts: flag()
    workers: whole(0, note="0 or 1: in this process")

    @field_validator("planner_options")
    @classmethod
    def _options_the_planner_takes(cls, options: dict[str, Any], info: ValidationInfo) -> dict[str, Any]:
        """An option the planner does not take fails here, by its key, not in the first worker."""
        planner = info.data.get("planner")
        if planner is None:  # the planner itself was refused
            return options
        accepted = accepted_options(planner, options)
        for key in options:
            if key not in accepted:
                raise PydanticCustomError(
                    "unknown_key",
                    "{planner} has no option {key}",
                    {"key": key, "known": ", ".join(accepted), "planner": planner},
                )
        make_config(planner, **options)
        return options


def main(params_path: str = "params.yaml", backend: str | None = None) -> dict:
    return collect_expert(read_stage(params_path, "collect_expert", Settings), read_protocol(params_path), backend)


if __name__ == "__main__":
    parser = stage_arguments(__doc__)
    parser.add_argument(
        "--backend",
        choices=["process", "ray"],
        default=None,
        help="where the shards are made: process (this machine's cores) or ray (the cluster "
        "$RAY_ADDRESS names) [default: $GUIDE_BACKEND or process]",
    )
    args = parser.parse_args()
    run_stage_main(main, args.params, args.backend)
