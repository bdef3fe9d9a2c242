"""Time one `guide/Explore-v0` step against the simulator's own step with the same choice.

Usage: python benchmarks/bench_env.py [--count 3] [--side 100] [--seed 11] [--repeats 5] [--action neighbour]

Draws `--count` mazes of `--side` metres (pipeline/world/mazes.py, maze i from seed [seed, i]),
runs `greedy_utility` on each through `run_episode` and times its loop per waypoint: the
planner's decision plus the move, from the first `on_step` call (after the first scan and the
planner's reset) to the last; that loop is what an agent in the environment replaces. Then it
replays the recorded waypoints through `env.step` (one neighbour slot per waypoint, or with
`--action node` the waypoint's row), checks that the trajectory and the distance come out the
same, and times `env.step` alone (choosing the action is the agent's time, not the
environment's). Each figure is the best of `--repeats` runs of the episode; prints both per
maze, their total per step, and the ratio env / simulator (the target is at most 1.2).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

from pipeline.envs import ExploreEnv
from pipeline.planners import make_planner
from pipeline.world.maps import load_map
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import Episode, run_episode


def simulator_loop(path: Path, protocol: Protocol) -> tuple[float, list[tuple[float, float]], float]:
    """(seconds of run_episode's loop, the trajectory, the distance) of greedy_utility on one map."""
    marks: list[float] = []

    def on_step(_: Episode) -> None:
        marks.append(time.perf_counter())

    result = run_episode(load_map(path), make_planner("greedy_utility"), protocol, on_step=on_step)
    return marks[-1] - marks[0], result.trajectory, result.distance_m


def environment_loop(env: ExploreEnv, trajectory: list[tuple[float, float]]) -> tuple[float, list, float]:
    """(seconds spent in env.step, the trajectory, the distance) replaying `trajectory`'s waypoints."""
    env.reset(seed=0)
    spent, info = 0.0, {}
    for waypoint in trajectory[1:]:
        action = env.action_for_waypoint(waypoint)
        t0 = time.perf_counter()
        _, _, terminated, truncated, info = env.step(action)
        spent += time.perf_counter() - t0
        if terminated or truncated:
            break
    return spent, info["trajectory"], info["distance"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=3, help="mazes to draw")
    parser.add_argument("--side", type=float, default=100.0, help="maze side in metres")
    parser.add_argument("--seed", type=int, default=11, help="maze i is drawn from seed [seed, i]")
    parser.add_argument("--repeats", type=int, default=5, help="runs per maze; the best time counts")
    parser.add_argument("--action", choices=("neighbour", "node"), default="neighbour")
    args = parser.parse_args()
    protocol = Protocol()
    with tempfile.TemporaryDirectory() as folder:
        paths = [
            write_maze_png(
                generate_maze(MazeConfig(side_m=(args.side, args.side)), np.random.default_rng([args.seed, i])),
                Path(folder) / f"maze_{i:04d}.png",
            )
            for i in range(args.count)
        ]
        simulator_loop(paths[0], protocol)  # compile and warm the caches before timing anything
        print(
            f"{'maze':<10} {'waypoints':>9} {'distance m':>10} {'simulator ms/step':>18} {'env ms/step':>12} {'ratio':>6}"
        )
        total_sim = total_env = 0.0
        total_steps = 0
        for path in paths:
            sim_times, env_times = [], []
            env = ExploreEnv(map=str(path), action=args.action)
            for _ in range(args.repeats):
                seconds, trajectory, distance = simulator_loop(path, protocol)
                sim_times.append(seconds)
                env_seconds, env_trajectory, env_distance = environment_loop(env, trajectory)
                env_times.append(env_seconds)
                if env_trajectory != trajectory or abs(env_distance - distance) > 1e-9:
                    raise SystemExit(f"{path.name}: the environment's replay differs from run_episode's episode")
            steps = len(trajectory) - 1
            sim_ms, env_ms = min(sim_times) / steps * 1e3, min(env_times) / steps * 1e3
            total_sim, total_env, total_steps = (
                total_sim + min(sim_times),
                total_env + min(env_times),
                total_steps + steps,
            )
            print(
                f"{path.stem:<10} {steps:>9} {distance:>10.1f} {sim_ms:>18.3f} {env_ms:>12.3f} {env_ms / sim_ms:>6.2f}"
            )
        sim_ms, env_ms = total_sim / total_steps * 1e3, total_env / total_steps * 1e3
        print(f"{'all':<10} {total_steps:>9} {'':>10} {sim_ms:>18.3f} {env_ms:>12.3f} {env_ms / sim_ms:>6.2f}")


if __name__ == "__main__":
    main()
