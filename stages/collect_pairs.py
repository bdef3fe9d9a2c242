"""DVC stage: Stage I (observed, ground-truth) node-image pairs from rollouts in training mazes.

Reads the `collect_pairs` section (and the shared `protocol`); writes shards and a
manifest to data/pairs/ and a picture of a few pairs to reports/pairs_preview.png.
"""

from __future__ import annotations

from pipeline.common.params import complete_section, load_params
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.workflows.collect_pairs import collect_pairs
from pipeline.world.protocol import Protocol

KEYS = ("seed", "pairs", "pairs_per_shard", "planners", "snapshot_every", "stop_steps", "workers", "backend")


def main(params_path: str = "params.yaml", backend: str | None = None) -> dict:
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
