"""Time one team decision: the coordinated team planners for N robots on one CPU thread.

Usage: python benchmarks/bench_team.py [--maps data/mazes/test] [--count 4] [--robots 4]
                                       [--planner greedy_utility --planner guide_tsp --planner guide]
Runs a whole team episode of each planner on the first `--count` maps and times every decision
(one robot's `plan()` call: its graph update, the prediction and the route split for the team,
and for `guide` the policy's vote). Prints the median, p95 and maximum per planner, with the
mean makespan. One thread for torch, numba and BLAS, as one benchmark worker has.
"""

from __future__ import annotations

import os

for _variable in ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS", "NUMBA_NUM_THREADS"):
    os.environ[_variable] = "1"  # before numpy, torch and numba read them

import argparse  # noqa: E402
from pathlib import Path  # noqa: E402

import numpy as np  # noqa: E402
import torch  # noqa: E402

from pipeline.planners.team.registry import make_team_planner  # noqa: E402
from pipeline.world.maps import list_maps, load_map  # noqa: E402
from pipeline.world.protocol import Protocol  # noqa: E402
from pipeline.world.team import run_team_episode  # noqa: E402


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--maps", type=Path, default=Path("data/mazes/test"))
    parser.add_argument("--count", type=int, default=4)
    parser.add_argument("--robots", type=int, default=4)
    parser.add_argument("--planner", action="append", default=None)
    args = parser.parse_args()
    torch.set_num_threads(1)
    maps = list_maps(args.maps)[: args.count]
    if not maps:
        raise SystemExit(f"{args.maps}: no maps")
    for name in args.planner or ["greedy_utility", "guide_tsp", "guide"]:
        decisions, makespans = [], []
        for path in maps:
            result = run_team_episode(load_map(path), make_team_planner(name), Protocol(), args.robots)
            decisions += [ms for robot in result.decision_ms for ms in robot]
            makespans.append(result.makespan_m)
        ms = np.asarray(decisions)
        print(
            f"{name}, {args.robots} robots, {len(maps)} maps: {ms.size} decisions, median {np.median(ms):.1f} ms, "
            f"p95 {np.percentile(ms, 95):.1f} ms, max {ms.max():.1f} ms; mean makespan {np.mean(makespans):.1f} m",
            flush=True,
        )


if __name__ == "__main__":
    main()
