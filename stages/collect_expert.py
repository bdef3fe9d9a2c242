"""DVC stage: Stage II expert episodes on training mazes, as raw per-step state.

Reads the `collect_expert` section (and the shared `protocol`); writes shards and a
manifest to data/expert/ and a picture of one stored episode to
reports/expert_episode.png (rebuilt from the shard, so it also checks the round trip).
"""

from __future__ import annotations

from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.collect_expert import Settings, collect_expert


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
