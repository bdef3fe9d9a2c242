"""The executor's two engines side by side on one benchmark: wall time and equal trajectories.

Usage: python benchmarks/bench_engines.py [--maps data/mazes/test] [--planner NAME ...] [--workers 2]
                                          [--params params.yaml]

Runs the same benchmark (default: the `benchmark` stage's planners from params.yaml on the
default test mazes, at its protocol) on the process engine and then on Ray (a private local
Ray of `workers` CPUs, or the cluster RAY_ADDRESS names), prints each wall time, Ray's as a
multiple of the process engine's, and whether every trajectory file is byte-identical.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import yaml

from pipeline.evaluation.benchmark import run_benchmark
from pipeline.world.maps import list_maps
from pipeline.world.protocol import Protocol


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--maps", default="data/mazes/test")
    parser.add_argument("--planner", action="append", help="planner spec (repeat) [default: the benchmark stage's]")
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--params", default="params.yaml")
    args = parser.parse_args()
    params = yaml.safe_load(Path(args.params).read_text())
    planners = args.planner or params["benchmark"]["planners"]
    protocol = Protocol.from_dict(params["protocol"])
    maps = list_maps(args.maps)
    seconds = {}
    with tempfile.TemporaryDirectory() as scratch:
        for engine in ("process", "ray"):
            started = time.perf_counter()
            run_benchmark(maps, planners, protocol, Path(scratch) / engine, workers=args.workers, backend=engine)
            seconds[engine] = time.perf_counter() - started
            print(f"{engine}: {seconds[engine]:.1f} s")
        files = sorted(
            p.relative_to(Path(scratch) / "process")
            for p in (Path(scratch) / "process").glob("*/*.csv")
            if not p.name.endswith(".steps.csv")
        )
        same = all(
            (Path(scratch) / "process" / f).read_bytes() == (Path(scratch) / "ray" / f).read_bytes() for f in files
        )
    print(
        f"{len(maps)} maps x {len(planners)} planners, {args.workers} workers: ray / process = "
        f"{seconds['ray'] / seconds['process']:.2f}; {len(files)} trajectories byte-identical: {same}"
    )


if __name__ == "__main__":
    main()
