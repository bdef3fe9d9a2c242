"""Time one `drl` decision on one CPU thread, beside `nearest_frontier`'s in the same run.

Usage: python benchmarks/bench_drl.py [--count 3] [--side 100] [--seed 11] [--checkpoint PATH]

Draws `--count` mazes of `--side` metres (maze i from seed [seed, i]) and runs `drl` (the
pipeline's policy in models/drl, else the shipped one, or `--checkpoint`) and `nearest_frontier`
on each through `run_episode`, with torch on one thread. A decision is the planner's whole
`plan` call, as the simulator times it: folding the scan into the lattice graph, building the
observation, the network's forward pass and the choice. Prints each maze's median and 95th
percentile per planner, the median over every decision, and the ratio drl / nearest_frontier
(the issue's target: a drl median of at most 20 ms).
"""

from __future__ import annotations

import argparse
import tempfile
from pathlib import Path

import numpy as np
import torch

from pipeline.planners import make_planner
from pipeline.world.maps import load_map
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=3, help="mazes to draw")
    parser.add_argument("--side", type=float, default=100.0, help="maze side (m)")
    parser.add_argument("--seed", type=int, default=11)
    parser.add_argument("--checkpoint", default=None, help="drl export [default: models/drl/policy.pt, else shipped]")
    args = parser.parse_args()
    torch.set_num_threads(1)
    protocol = Protocol()
    config = MazeConfig(side_m=(args.side, args.side), cell_size=protocol.cell_size)
    planners = {"drl": {"checkpoint": args.checkpoint}, "nearest_frontier": {}}
    times: dict[str, list[float]] = {name: [] for name in planners}
    with tempfile.TemporaryDirectory() as folder:
        for i in range(args.count):
            path = Path(folder) / f"maze_{i:04d}.png"
            write_maze_png(generate_maze(config, np.random.default_rng([args.seed, i])), path)
            ground_truth = load_map(path)
            for name, options in planners.items():
                result = run_episode(ground_truth, make_planner(name, **options), protocol)
                ms = np.asarray(result.decision_ms)
                times[name].extend(ms.tolist())
                print(
                    f"{path.name} {name:>16}: {len(ms):4d} decisions, median {np.median(ms):6.2f} ms, "
                    f"p95 {np.percentile(ms, 95):6.2f} ms, {result.distance_m:6.1f} m, complete {result.complete}"
                )
    medians = {name: float(np.median(values)) for name, values in times.items()}
    for name, value in medians.items():
        print(f"all mazes {name:>16}: median {value:.2f} ms over {len(times[name])} decisions")
    print(f"ratio drl / nearest_frontier (median decision): {medians['drl'] / medians['nearest_frontier']:.2f}")


if __name__ == "__main__":
    main()
