"""Table I at the real-robot scale on a folder of floors, with the base rate beside the precision.

Usage: python benchmarks/table1_real_robot.py --maps FOLDER [--checkpoint INPAINTER] [--steps 30 60 90 120]

Explores each floor with `nearest_frontier` at the real-robot protocol (0.2 m cells, 1 m lattice,
10 m lidar) and, at each step, checks the region-evaluated predicted nodes V_u against the ground
truth (`pipeline.evaluation.predictor_eval`). The inpainter is the one a planner picks at that
protocol (`pipeline/models/defaults.py`: `models/` when trained there, else the shipped
real-robot one) unless `--checkpoint` names one. Prints per step the precision, the base rate
(the free share of the nodes the network was asked about in the kept regions: what calling
them all free scores), the V_u nodes and the maps reached.
"""

from __future__ import annotations

import argparse

from pipeline.evaluation.predictor_eval import evaluate_predictor, load_inpaint_fn
from pipeline.models.defaults import pick_model
from pipeline.world.maps import list_maps
from pipeline.world.protocol import PAPER_REAL_ROBOT


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--maps", required=True)
    parser.add_argument("--checkpoint", default=None)
    parser.add_argument("--steps", type=int, nargs="+", default=[30, 60, 90, 120])
    args = parser.parse_args()
    checkpoint = args.checkpoint or pick_model("inpainter", PAPER_REAL_ROBOT)
    frame = evaluate_predictor(
        list_maps(args.maps), load_inpaint_fn(checkpoint), steps=args.steps, protocol=PAPER_REAL_ROBOT, progress=True
    )
    print(f"inpainter: {checkpoint}")
    print("| step | precision | base rate | V_u nodes | maps |")
    print("|---:|---:|---:|---:|---:|")
    for row in frame.itertuples(index=False):
        print(
            f"| {row.step} | {100 * row.precision:.1f} % | {100 * row.base_rate:.1f} % | {row.predicted_nodes} | {row.maps} |"
        )


if __name__ == "__main__":
    main()
