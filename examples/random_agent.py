"""A random agent in guide/Explore-v0 that only takes valid actions (docs/environment.md)."""

import argparse

import gymnasium
import numpy as np

import pipeline  # noqa: F401  (registers guide/Explore-v0)

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--map", default="maze", help="a map file, a folder of maps, or maze (a new maze each episode)")
parser.add_argument("--side", type=float, default=50.0, help="side of the generated mazes (m)")
parser.add_argument("--episodes", type=int, default=2)
parser.add_argument("--seed", type=int, default=0)
args = parser.parse_args()

env = gymnasium.make("guide/Explore-v0", map=args.map, maze_side_m=args.side)
rng = np.random.default_rng(args.seed)
for episode in range(args.episodes):
    obs, info = env.reset(seed=args.seed + episode)
    total, done = 0.0, False
    while not done:
        action = rng.choice(np.flatnonzero(obs["action_mask"]))  # a random valid action
        obs, reward, terminated, truncated, info = env.step(action)
        total += reward
        done = terminated or truncated
    outcome = "complete" if info["complete"] else "truncated"
    print(f"{info['map_name']}: reward {total:.1f}, {info['distance']:.0f} m, "
          f"{info['explored_share']:.0%} explored, {outcome} after {info['steps']} steps")
env.close()
