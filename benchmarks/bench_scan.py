"""Time one 20 m lidar scan (720 rays) and one nearest_frontier episode on a 100 m maze.

Usage: python benchmarks/bench_scan.py [--maze PATH] [--repeats N]
Without --maze it generates a 100 m maze with the project's generator.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from pipeline.planners import make_planner
from pipeline.world.maps import load_maze_png
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import Lidar
from pipeline.world.simulator import run_episode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--maze", type=Path, help="a maze PNG (default: a generated 100 m maze)")
    parser.add_argument("--repeats", type=int, default=500)
    args = parser.parse_args()
    if args.maze is None:
        args.maze = Path(tempfile.mkdtemp()) / "maze.png"
        write_maze_png(generate_maze(MazeConfig(side_m=(100.0, 100.0)), np.random.default_rng(0)), args.maze)
    ground_truth = load_maze_png(args.maze)
    protocol = Protocol()
    free_cells = np.argwhere(ground_truth.free)
    rng = np.random.default_rng(0)
    positions = free_cells[rng.integers(0, len(free_cells), size=args.repeats)]
    lidar = Lidar(ground_truth.free, protocol.sensor_range_cells)  # as the simulator holds it
    lidar.scan(ground_truth.start_cell)  # warm the ray table
    times = []
    for row, col in positions:
        t0 = time.perf_counter()
        lidar.scan((int(col), int(row)))
        times.append(time.perf_counter() - t0)
    times_ms = np.array(times) * 1e3
    print(
        f"scan (720 rays, {protocol.sensor_range} m): median {np.median(times_ms):.3f} ms, "
        f"p95 {np.percentile(times_ms, 95):.3f} ms over {args.repeats} random free cells"
    )
    t0 = time.perf_counter()
    result = run_episode(ground_truth, make_planner("nearest_frontier"), protocol)
    elapsed = time.perf_counter() - t0
    print(
        f"nearest_frontier episode on {args.maze.name}: {elapsed:.2f} s, {result.steps} waypoints, "
        f"{result.distance_m:.1f} m, complete={result.complete}, "
        f"decision median {np.median(result.decision_ms):.2f} ms"
    )


if __name__ == "__main__":
    main()
