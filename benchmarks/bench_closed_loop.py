"""The robot path in closed loop against the simulator, paired, on fresh maps.

Usage: python benchmarks/bench_closed_loop.py [--family maze|office] [--count 20] [--seed 9100]
                                              [--planner greedy_utility --planner guide_tsp --planner guide]
                                              [--workers 2]

Draws `--count` fresh maps (100 m mazes at the maze benchmark's protocol, or real-robot office
floors of 40 m at the real-robot protocol), then per planner runs each map twice: in the
simulator (`run_episode`) and through `ExplorationSession` in the closed loop of
`pipeline.robot.closed_loop` (SLAM maps at 0.05 m through CDR, a 0.1 m noisy pose, a robot that
drives along free cells, one goal in twenty failing). Prints, per planner, how many episodes
completed, the mean distance of each, and the closed loop's paired difference to the simulator
(mean +- the 95 % half-width).
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np
import torch

from pipeline.evaluation.statistics import student_t_975
from pipeline.planners import make_planner
from pipeline.robot import ExplorationSession
from pipeline.robot.closed_loop import run_closed_loop
from pipeline.world.maps import load_map
from pipeline.world.mazes import MazeConfig, generate_maze_set
from pipeline.world.offices import OfficeConfig, generate_office_set
from pipeline.world.protocol import PAPER_REAL_ROBOT, Protocol
from pipeline.world.simulator import run_episode


def draw_maps(family: str, count: int, seed: int, folder: str) -> tuple[list, Protocol]:
    if family == "maze":
        protocol = Protocol()
        paths = generate_maze_set(MazeConfig(side_m=(100.0, 100.0)), count, folder, seed=seed)
    else:
        protocol = PAPER_REAL_ROBOT
        config = OfficeConfig.for_scale("real_robot", side_m=40.0, cell_size=protocol.cell_size)
        paths = generate_office_set(config, count, folder, seed, progress=False)
    return [load_map(path, cell_size=protocol.cell_size) for path in paths], protocol


def paired_episode(name: str, world, protocol: Protocol, index: int) -> tuple[float, float, bool]:
    """(simulator distance, closed-loop distance, closed loop complete) of one planner on one map."""
    torch.set_num_threads(1)
    simulated = run_episode(world, make_planner(name), protocol, seed=index).distance_m
    result = run_closed_loop(world, ExplorationSession(name, protocol, seed=index), seed=index)
    return simulated, result.distance_m, bool(result.complete)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--family", choices=("maze", "office"), default="maze")
    parser.add_argument("--count", type=int, default=20)
    parser.add_argument("--seed", type=int, default=9100)
    parser.add_argument("--planner", action="append", default=None)
    parser.add_argument("--workers", type=int, default=1, help="maps run in parallel processes")
    args = parser.parse_args()
    torch.set_num_threads(1)
    with tempfile.TemporaryDirectory() as folder:
        maps, protocol = draw_maps(args.family, args.count, args.seed, folder)
    print(f"{len(maps)} fresh {args.family} maps (seed {args.seed})")
    for name in args.planner or ["greedy_utility", "guide_tsp", "guide"]:
        started = time.perf_counter()
        with ProcessPoolExecutor(args.workers) as pool:
            results = list(pool.map(paired_episode, [name] * len(maps), maps, [protocol] * len(maps), range(len(maps))))
        simulated, looped, completed = zip(*results)
        complete = sum(completed)
        sim, loop = np.asarray(simulated), np.asarray(looped)
        diff = (loop - sim) / sim.mean()
        half = student_t_975(len(diff) - 1) * diff.std(ddof=1) / math.sqrt(len(diff)) if len(diff) > 1 else float("nan")
        print(
            f"{name:<16} closed loop complete {complete}/{len(maps)}  simulator {sim.mean():7.1f} m  "
            f"closed loop {loop.mean():7.1f} m  paired {100 * diff.mean():+.1f} % +- {100 * half:.1f}  "
            f"({time.perf_counter() - started:.0f} s)"
        )


if __name__ == "__main__":
    main()
