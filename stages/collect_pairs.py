"""DVC stage: Stage I (observed, ground-truth) node-image pairs from rollouts in training mazes.

Reads the `collect_pairs` section (and the shared `protocol`); writes shards and a
manifest to data/pairs/ and a picture of a few pairs to reports/pairs_preview.png.
"""

from __future__ import annotations

from pipeline.common.config import Section, list_of, pair, satisfies, whole
from pipeline.planners import planner_config
from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.collect_pairs import collect_pairs


class Settings(Section):
    """The `collect_pairs` section of params.yaml."""

    seed: whole(0)
    pairs: whole(1)
    pairs_per_shard: whole(1)
    planners: list_of(satisfies(planner_config, "a registered planner name", str))  # each rollout builds one by name
    snapshot_every: whole(1, note="steps")
    stop_steps: pair(whole(1, note="steps"))
    workers: whole(0, note="0 or 1: in this process")


def main(params_path: str = "params.yaml", backend: str | None = None) -> dict:
    return collect_pairs(read_stage(params_path, "collect_pairs", Settings), read_protocol(params_path), backend)


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
