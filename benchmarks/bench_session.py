"""Time a robot session's decision: one `plan()` on a SLAM map given as a fine OccupancyGrid.

Usage: python benchmarks/bench_session.py [--side 60] [--resolution 0.05] [--steps 40] [--repeats 20]
                                          [--planner guide --planner greedy_utility] [--protocol real_robot]

Draws one office floor of `--side` metres at the real-robot scale, explores it with greedy_utility
for `--steps` waypoints, then one more per repeat, and turns each belief into an OccupancyGrid of
`--resolution` metre cells with occupancy probabilities, cropped to the known area, as a SLAM map
grows. Each repeat hands the session its message (`update_map`: the conversion to the protocol's
cells) and the pose, then asks for a fresh plan (`plan(force=True)`). Prints the median and p95 of the conversion, the
planning and the whole decision, in milliseconds, on one torch thread.
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np
import torch

from pipeline.planners import make_planner
from pipeline.robot import ExplorationSession
from pipeline.robot.closed_loop import grid_message, slam_map
from pipeline.robot.session import resolve_protocol
from pipeline.world.maps import load_map
from pipeline.world.offices import OfficeConfig, generate_office_set
from pipeline.world.simulator import Episode


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--side", type=float, default=60.0, help="floor side (m)")
    parser.add_argument("--resolution", type=float, default=0.05, help="the SLAM map's cell size (m)")
    parser.add_argument("--steps", type=int, default=40, help="greedy waypoints before the timed decisions")
    parser.add_argument("--repeats", type=int, default=20)
    parser.add_argument("--planner", action="append", default=None)
    parser.add_argument("--protocol", default="real_robot")
    parser.add_argument("--seed", type=int, default=7400)
    args = parser.parse_args()
    torch.set_num_threads(1)
    protocol = resolve_protocol(args.protocol)
    config = OfficeConfig.for_scale("real_robot", side_m=args.side, cell_size=protocol.cell_size)
    with tempfile.TemporaryDirectory() as folder:
        (path,) = generate_office_set(config, 1, folder, args.seed, progress=False)
        floor = load_map(path, cell_size=protocol.cell_size)
    episode = Episode(floor, protocol)
    greedy = make_planner("greedy_utility")
    greedy.reset(floor.frame, protocol, 0)
    for _ in range(args.steps):
        waypoints = greedy.plan(episode.observe())
        if not waypoints:
            break
        episode.move(waypoints[0])
    rng = np.random.default_rng(0)
    moments = []  # (message, pose) after each further greedy waypoint: every decision sees a grown map
    for _ in range(args.repeats + 1):
        moments.append((grid_message(slam_map(episode, args.resolution, rng)), episode.position))
        waypoints = greedy.plan(episode.observe())
        if waypoints:
            episode.move(waypoints[0])
    first = moments[0][0]
    print(
        f"{args.side:g} m floor, beliefs after {args.steps} to {args.steps + args.repeats} greedy waypoints, as "
        f"OccupancyGrids of {args.resolution:g} m cells (the first {first.width} x {first.height})"
    )
    for name in args.planner or ["guide", "greedy_utility"]:
        session = ExplorationSession(name, protocol)
        session.update_pose(0.0, 0.0)
        convert, decide, whole = [], [], []
        for repeat, (message, position) in enumerate(moments):
            t0 = time.perf_counter()
            session.update_map(message)
            t1 = time.perf_counter()
            session.update_pose(*position, 0.0)
            session.plan(force=True)
            t2 = time.perf_counter()
            if repeat:  # the first decision loads the models and builds the graph from scratch
                convert.append((t1 - t0) * 1e3)
                decide.append((t2 - t1) * 1e3)
                whole.append((t2 - t0) * 1e3)
        print(
            f"{name:<16} conversion {np.median(convert):7.1f} ms (p95 {np.percentile(convert, 95):.1f})  "
            f"planning {np.median(decide):7.1f} ms (p95 {np.percentile(decide, 95):.1f})  "
            f"decision {np.median(whole):7.1f} ms (p95 {np.percentile(whole, 95):.1f})"
        )


if __name__ == "__main__":
    main()
