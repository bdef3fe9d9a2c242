"""Seconds per `expert` episode on 100 m mazes, with the `optimal` and `expert` distances.

Usage: python benchmarks/bench_expert.py [--maze PATH ...] [--count N] [--seed S] [--nf]
Without --maze it generates N 100 m mazes with the project's generator, maze i drawn from
default_rng([S, 1, i]). `optimal` runs under the oracle motion rule
(`pipeline.planners.references.coverage.run_oracle_episode`), `expert` and `nearest_frontier` under the
simulator's own rule (`pipeline.world.simulator.run_episode`). The coverage model (ground-truth
graph, scans, all-pairs paths) is built once per map and shared; its time is printed apart.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from pipeline.planners import make_planner
from pipeline.planners.references.coverage import run_oracle_episode
from pipeline.planners.references.coverage_model import coverage_model
from pipeline.world.maps import load_maze_png
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--maze", type=Path, nargs="*", help="maze PNGs (default: generated 100 m mazes)")
    parser.add_argument("--count", type=int, default=1, help="generated mazes (default 1)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--nf", action="store_true", help="also run nearest_frontier")
    args = parser.parse_args()
    mazes = list(args.maze or [])
    if not mazes:
        directory = Path(tempfile.mkdtemp())
        for i in range(args.count):
            image = generate_maze(MazeConfig(side_m=(100.0, 100.0)), np.random.default_rng([args.seed, 1, i]))
            mazes.append(write_maze_png(image, directory / f"maze_{i:04d}.png"))
    protocol = Protocol()
    header = f"{'map':<16}{'model s':>8}{'NF m':>9}{'optimal m':>11}{'opt s':>7}{'expert m':>10}{'exp s':>7}{'gap':>8}{'viol':>5}"
    print(header)
    rows = []
    for path in mazes:
        ground_truth = load_maze_png(path)
        t0 = time.perf_counter()
        coverage_model(ground_truth, protocol)
        model_s = time.perf_counter() - t0
        nf = float("nan")
        if args.nf:
            nf = run_episode(ground_truth, make_planner("nearest_frontier"), protocol).distance_m
        t0 = time.perf_counter()
        optimal = run_oracle_episode(ground_truth, make_planner("optimal"), protocol)
        optimal_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        expert = run_episode(ground_truth, make_planner("expert"), protocol)
        expert_s = time.perf_counter() - t0
        gap = expert.distance_m / optimal.distance_m - 1.0
        flags = "" if optimal.complete and expert.complete else "  INCOMPLETE"
        print(
            f"{path.name:<16}{model_s:>8.2f}{nf:>9.1f}{optimal.distance_m:>11.1f}{optimal_s:>7.2f}"
            f"{expert.distance_m:>10.1f}{expert_s:>7.2f}{gap:>8.3f}{expert.motion_violations:>5d}{flags}",
            flush=True,
        )
        rows.append((model_s, nf, optimal.distance_m, optimal_s, expert.distance_m, expert_s))
    if len(rows) > 1:
        m = np.nanmean(np.array(rows), axis=0) if args.nf else np.mean(np.array(rows), axis=0)
        print(
            f"{'mean':<16}{m[0]:>8.2f}{m[1]:>9.1f}{m[2]:>11.1f}{m[3]:>7.2f}{m[4]:>10.1f}{m[5]:>7.2f}"
            f"{m[4] / m[2] - 1.0:>8.3f}"
        )
    print("expert seconds per episode exclude the shared coverage model (column 'model s').")


if __name__ == "__main__":
    main()
