"""Gymnasium environments over the simulator: `guide/Explore-v0` (`ExploreEnv`, docs/environment.md).

`import pipeline` registers the id; `gymnasium.make("guide/Explore-v0", map=...)` builds one.
"""

from pipeline.envs.configuration_explore import ExploreEnvConfig
from pipeline.envs.explore_env import ExploreEnv

ENV_ID = "guide/Explore-v0"

__all__ = ["ENV_ID", "ExploreEnv", "ExploreEnvConfig"]
