"""The settings of the team exploration environment (`TeamExploreEnv`): one frozen object, checked once.

They are `ExploreEnvConfig`'s (maps, protocol, actions, observation sizes, reward weights: a team
robot sees and is rewarded as the single robot of `guide/Explore-v0` is) plus the team's own: how
many robots, where they start, how far they can talk, and how many environment steps an episode
may take. A bad value fails when the environment is made, with the same one-line ValueError.
"""

from __future__ import annotations

from dataclasses import fields
from typing import Annotated

from pipeline.common.config import config_dataclass, list_of, maybe, positive, real, whole
from pipeline.envs.configuration_explore import ExploreEnvConfig
from pipeline.world.team import MAX_ROBOTS


@config_dataclass
class TeamExploreEnvConfig(ExploreEnvConfig):
    """What `TeamExploreEnv` runs: `ExploreEnvConfig`'s fields and the team's.

    `max_steps` keeps its protocol meaning for each robot (a robot that has made that many moves
    stops, as in `run_team_episode`); the environment's own step count is bounded by `step_limit`.
    The belief image of `guide/Explore-v0` is not offered: each robot's observation is its graph.
    """

    robots: Annotated[int, whole(1, MAX_ROBOTS)] = 2  # agents robot_0 .. robot_{robots-1}
    # each robot's start in metres from the map's start, on the node lattice (None: all at the map's start)
    starts: Annotated[
        list[list[float]] | None,
        maybe(list_of(list_of(real(), 2, "an (x, y) pair of finite numbers")), "every robot at the map's start"),
    ] = None
    comm_range_m: Annotated[float | None, maybe(positive("metres"), "full communication: one shared belief")] = None
    step_limit: Annotated[int | None, maybe(whole(1), "robots * max_steps")] = (
        None  # environment steps before the episode is truncated
    )

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.belief_image:
            raise ValueError("belief_image is not offered by the team environment; each robot observes its graph")
        if self.starts is not None:
            if len(self.starts) != self.robots:
                raise ValueError(f"starts gives {len(self.starts)} positions for {self.robots} robots")
            for k, start in enumerate(self.starts):
                if len(start) != 2:
                    raise ValueError(f"starts[{k}] must be an (x, y) pair, got {list(start)}")

    @property
    def steps_allowed(self) -> int:
        """The environment steps an episode may take before it is truncated."""
        return self.step_limit if self.step_limit is not None else self.robots * self.max_steps

    def explore_config(self) -> ExploreEnvConfig:
        """The single-robot settings inside these: what each robot's graph observation is built with."""
        return ExploreEnvConfig(**{f.name: getattr(self, f.name) for f in fields(ExploreEnvConfig)})
