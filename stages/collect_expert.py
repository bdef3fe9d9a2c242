"""DVC stage: Stage II expert episodes on training mazes, as raw per-step state.

Reads the `collect_expert` section (and the shared `protocol`); writes shards and a
manifest to data/expert/ and a picture of one stored episode to
reports/expert_episode.png (rebuilt from the shard, so it also checks the round trip).
"""

from __future__ import annotations

from pipeline.common.params import complete_section, load_params
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.collect_expert import collect_expert
from pipeline.world.protocol import Protocol

KEYS = ("seed", "episodes", "episodes_per_shard", "planner", "horizon", "random_starts", "workers", "backend")


def main(params_path: str = "params.yaml", backend: str | None = None) -> dict:
    params = load_params(params_path)
    section = complete_section(params, "collect_expert", params_path, KEYS)
    protocol = Protocol.from_dict(params.get("protocol") or {})
    return collect_expert(section, protocol, backend)


if __name__ == "__main__":
    parser = stage_arguments(__doc__)
    parser.add_argument("--backend", choices=["process", "ray"], default=None,
                        help="process (default) or ray (pip install '.[ray]')")
    args = parser.parse_args()
    run_stage_main(main, args.params, args.backend)
