"""Train sb3-contrib's MaskablePPO in guide/Explore-v0 on small generated mazes (docs/environment.md)."""

import argparse

import gymnasium
from sb3_contrib import MaskablePPO

import pipeline  # noqa: F401  (registers guide/Explore-v0)

parser = argparse.ArgumentParser(description=__doc__)
parser.add_argument("--side", type=float, default=50.0, help="side of the generated mazes (m)")
parser.add_argument("--timesteps", type=int, default=4096, help="environment steps to train for")
parser.add_argument("--max-steps", type=int, default=100, help="steps before an episode is truncated")
parser.add_argument("--seed", type=int, default=0)
parser.add_argument("--save", default=None, help="where to save the trained model (a .zip)")
args = parser.parse_args()

env = gymnasium.make("guide/Explore-v0", map="maze", maze_side_m=args.side, max_nodes=64,
                     max_steps=args.max_steps)
model = MaskablePPO("MultiInputPolicy", env, n_steps=256, batch_size=64, seed=args.seed, verbose=0)
model.learn(total_timesteps=args.timesteps)  # asks env.action_masks() before every action
if args.save:
    model.save(args.save)

obs, info = env.reset(seed=args.seed + 1_000_000)  # a maze it has not trained on
total, done = 0.0, False
while not done:
    action, _ = model.predict(obs, action_masks=obs["action_mask"].astype(bool), deterministic=True)
    obs, reward, terminated, truncated, info = env.step(action)
    total += reward
    done = terminated or truncated
print(f"{info['map_name']}: reward {total:.1f}, {info['distance']:.0f} m, "
      f"{info['explored_share']:.0%} explored in {info['steps']} steps")
env.close()
