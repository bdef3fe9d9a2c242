"""Time `guide` (and `dare`) decisions at several denoising-step counts K.

Usage: python benchmarks/bench_planner.py [--maps data/mazes/test] [--count 2] [--k 10 30 50 100]
                                          [--planner guide --planner dare] [--steps 60]
                                          [--option lookahead=3 ...]
Runs each planner for up to `--steps` waypoints on the first `--count` test mazes and
times every plan() call. A *full decision* is one that sampled a new action chunk: graph
update, node prediction, region evaluation, observation, K denoising steps; the other calls
execute the cached second step (T_a = 2) and only update the graph. Prints the median and
p95 of full decisions and of all calls, per planner and K. One torch thread, as in the
benchmark workers. `--option KEY=VALUE` passes planner options (as `guide:KEY=VALUE` in
`guide benchmark`), e.g. `--option lookahead=3` to time `guide` with its block-model lookahead;
then a second line per K gives the full decisions that rolled out (chose a new target) apart.
`--protocol real_robot` runs at the real-robot scale (0.2 m cells, 1 m lattice, 10 m lidar), where
the planners take the real-robot models, e.g. on a 60 m floor from
`guide mazes --kind office --scale real_robot --cell-size 0.2 --side 60 --count 1 --out runs/floor60`.
"""

from __future__ import annotations

import argparse
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch

from pipeline.planners import make_planner
from pipeline.planners.specs import parse_option_value
from pipeline.planners.wrapper import PlannerWrapper
from pipeline.world.maps import list_maps, load_map
from pipeline.world.protocol import PROTOCOLS
from pipeline.world.simulator import run_episode


class TimedPlanner(PlannerWrapper):
    """A planner, recording (milliseconds, sampled, rolled out) per plan() call."""

    def __init__(self, planner):
        super().__init__(planner)
        self.calls: list[tuple[float, bool, bool]] = []

    def plan(self, observation):
        t0 = time.perf_counter()
        out = self.inner.plan(observation)
        decision = self.inner.last_decision
        self.calls.append(
            (
                (time.perf_counter() - t0) * 1e3,
                bool(decision.get("sampled", False)),
                decision.get("lookahead_costs") is not None,
            )
        )
        return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--maps", default="data/mazes/test")
    parser.add_argument("--count", type=int, default=2)
    parser.add_argument("--k", type=int, nargs="+", default=[10, 30, 50, 100])
    parser.add_argument("--planner", action="append", default=None)
    parser.add_argument("--steps", type=int, default=60)
    parser.add_argument("--checkpoint", default=None)
    parser.add_argument(
        "--protocol",
        choices=sorted(PROTOCOLS),
        default="maze",
        help="maze: the benchmark's (0.4 m / 4 m / 20 m); real_robot: 0.2 m / 1 m / 10 m",
    )
    parser.add_argument(
        "--option", action="append", default=[], metavar="KEY=VALUE", help="a planner option; repeatable"
    )
    args = parser.parse_args()
    for option in args.option:
        if "=" not in option:
            parser.error(f"--option takes KEY=VALUE, got {option!r}")
    torch.set_num_threads(1)
    maps = list_maps(Path(args.maps))[: args.count]
    protocol = replace(PROTOCOLS[args.protocol], max_steps=args.steps)
    print(
        f"{'planner':<8} {'K':>4} {'full decision ms (median / p95)':>32} {'all calls ms (median)':>22} {'full decisions':>15}"
    )
    for name in args.planner or ["guide", "dare"]:
        for k in args.k:
            options = {key: parse_option_value(value) for key, value in (o.split("=", 1) for o in args.option)}
            options["num_inference_steps"] = k
            if args.checkpoint:
                options["checkpoint"] = args.checkpoint
            full, rolled, every = [], [], []
            for path in maps:
                timed = TimedPlanner(make_planner(name, **options))
                run_episode(load_map(path, None, protocol.cell_size), timed, protocol)
                calls = timed.calls[1:]  # the first call also loads the model
                full += [ms for ms, sampled, _ in calls if sampled]
                rolled += [ms for ms, sampled, rolled_out in calls if sampled and rolled_out]
                every += [ms for ms, _, _ in calls]
            print(
                f"{name:<8} {k:>4} {np.median(full):>18.1f} / {np.percentile(full, 95):>8.1f} {np.median(every):>22.1f} {len(full):>15}"
            )
            if rolled:
                print(
                    f"{'':<8} {'':>4} {np.median(rolled):>18.1f} / {np.percentile(rolled, 95):>8.1f} {'':>22} {len(rolled):>15}"
                    "  <- of which rolled out"
                )


if __name__ == "__main__":
    main()
