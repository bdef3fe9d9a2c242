"""Time `sampled_lookahead` decisions, and its distance beside gated greedy, on one 100 m maze.

Usage: python benchmarks/bench_lookahead.py [--maze PATH] [--checkpoint PATH] [--setting K SAMPLES ...] [--workers 2]
Without --maze it generates a 100 m maze with the project's generator; without --checkpoint the
planner finds its block model as always (models/block_model, else the shipped one). Each setting
is `k samples`; the default times the planner's defaults (3 4) and two cheaper ones (3 2, 2 1).
A decision's cost is k x samples rollouts of gated greedy to the end of a drawn map.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import torch

from pipeline.planners import make_planner
from pipeline.planners.wrapper import innermost
from pipeline.world.maps import load_maze_png
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--maze", type=Path, help="a maze PNG (default: a generated 100 m maze)")
    parser.add_argument("--checkpoint", help="a block model file (default: as the planner finds it)")
    parser.add_argument(
        "--setting",
        type=int,
        nargs=2,
        action="append",
        metavar=("K", "SAMPLES"),
        help="k and samples; repeat for several (default: 3 4, 3 2, 2 1)",
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=1,
        choices=(1, 2),
        help="processes for the rollouts (2: the planner's workers=2; the same routes)",
    )
    args = parser.parse_args()
    torch.set_num_threads(1)
    if args.maze is None:
        args.maze = Path(tempfile.mkdtemp()) / "maze.png"
        write_maze_png(generate_maze(MazeConfig(side_m=(100.0, 100.0)), np.random.default_rng(0)), args.maze)
    ground_truth = load_maze_png(args.maze)
    protocol = Protocol()
    started = time.perf_counter()
    gated = run_episode(ground_truth, make_planner("greedy_utility", sliver_gate=True), protocol, 0)
    print(
        f"gated greedy: {gated.distance_m:.1f} m, {np.median(gated.decision_ms):.1f} ms median a decision "
        f"({time.perf_counter() - started:.1f} s)"
    )
    for k, samples in args.setting or [(3, 4), (3, 2), (2, 1)]:
        planner = make_planner(
            "sampled_lookahead", k=k, samples=samples, checkpoint=args.checkpoint, workers=args.workers
        )
        started = time.perf_counter()
        result = run_episode(ground_truth, planner, protocol, 0)
        ms = np.asarray(result.decision_ms)
        print(
            f"sampled_lookahead k={k} samples={samples}: {result.distance_m:.1f} m "
            f"({'complete' if result.complete else result.failure}), {np.median(ms):.0f} ms median, "
            f"{np.percentile(ms, 95):.0f} ms p95 a decision over {ms.size} ({time.perf_counter() - started:.0f} s; "
            f"{innermost(planner).model_source}; {args.workers} process{'es' if args.workers > 1 else ''})"
        )


if __name__ == "__main__":
    main()
