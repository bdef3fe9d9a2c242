"""DVC stage: Stage I (observed, ground-truth) node-image pairs from rollouts in training mazes.

Reads the `collect_pairs` section (and the shared `protocol`); writes shards and a
manifest to data/pairs/ and a picture of a few pairs to reports/pairs_preview.png.
"""

from __future__ import annotations

from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.workflows.collect_pairs import Settings, collect_pairs


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
