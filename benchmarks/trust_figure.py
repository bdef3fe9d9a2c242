"""The trust in predictions over an episode where the predictions fail: a figure.

Usage: python benchmarks/trust_figure.py [--seed 5] [--side 30] [--out docs/trust_failing.png]

Draws one building floor and runs `guide_tsp` on it at the real-robot protocol with an
inpainter that is always wrong (free exactly where the ground truth is not: a stand-in for a
network trained on other buildings), and writes the episode's final figure, whose strip under
the map draws the planner's trust against the distance travelled. Prints the record at the end
and the same floor's distance with the predictions believed in full (`trust=false`).
"""

from __future__ import annotations

import argparse
import tempfile

import numpy as np

from pipeline.planners import make_planner
from pipeline.planners.wrapper import innermost
from pipeline.prediction.node_image import ground_truth_states, node_states_image
from pipeline.prediction.node_predictor import pad_to_multiple
from pipeline.reporting.panels import render_final
from pipeline.world.building_config import BuildingConfig
from pipeline.world.buildings import generate_building_set
from pipeline.world.maps import load_maze_png
from pipeline.world.protocol import PAPER_REAL_ROBOT
from pipeline.world.simulator import final_belief, run_episode


def always_wrong(ground_truth, holder: dict):
    """Free probability 1 exactly at the lattice nodes the ground truth has occupied."""

    def inpaint(image: np.ndarray) -> np.ndarray:
        graph = innermost(holder["planner"]).graph
        truth = node_states_image(graph, ground_truth_states(graph, ground_truth.free))
        padded, _ = pad_to_multiple(truth, 8, 255)
        return (padded == 0).astype(np.float32) if padded.shape == image.shape else np.zeros(image.shape, np.float32)

    return inpaint


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--side", type=float, default=30.0)
    parser.add_argument("--out", default="docs/trust_failing.png")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory() as folder:
        path = generate_building_set(BuildingConfig(side_m=args.side), 1, folder, seed=[args.seed], progress=False)[0]
        world = load_maze_png(path, cell_size=PAPER_REAL_ROBOT.cell_size)
    distances = {}
    for label, options in (("trusted", {}), ("believed", {"trust": False})):
        holder: dict = {}
        planner = make_planner("guide_tsp", inpaint=always_wrong(world, holder), min_component=0, **options)
        holder["planner"] = planner
        result = run_episode(world, planner, PAPER_REAL_ROBOT, seed=0)
        result.planner = f"guide_tsp, always-wrong inpainter, {label}"
        distances[label] = result.distance_m
        if label == "trusted":
            print("record at the end:", planner.trust_state.as_dict())
            render_final(
                result,
                world,
                final_belief(world, result.trajectory, PAPER_REAL_ROBOT),
                graph=innermost(planner).graph,
                path=args.out,
            )
    print(f"distance: trusted {distances['trusted']:.1f} m, believed {distances['believed']:.1f} m; wrote {args.out}")


if __name__ == "__main__":
    main()
