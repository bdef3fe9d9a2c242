"""Training the `drl` policy by reinforcement learning in `guide/Explore-v0` (the `train_drl` stage).

The algorithm is sb3-contrib's MaskablePPO: PPO whose categorical policy never samples a masked
action, here the window slots without a known-free edge. Its actor and critic are one
`DRLPolicy` (`pipeline.models.modeling_drl`): `DRLFeatures` runs it on SB3's preprocessed
observation and hands SB3 the 25 slot logits and the value, and `DRLActorCritic` replaces SB3's
heads by identities, so every weight trained is the exported policy's. Environments draw a
fresh maze at every reset, one side length per environment (`maze_sides_m`, round robin).
"""

from __future__ import annotations

import json
import time
from dataclasses import asdict
from pathlib import Path
from typing import Annotated, Any, Callable, cast

import numpy as np
import torch
from gymnasium import Env, spaces
from sb3_contrib import MaskablePPO
from sb3_contrib.common.maskable.policies import MaskableActorCriticPolicy
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnv
from torch import nn

from pipeline.common.atomic import atomic_write_text
from pipeline.common.config import any_of, config_dataclass, flag, fraction, list_of, positive, real, validate, whole
from pipeline.envs.explore_env import ExploreEnv
from pipeline.models.configuration_drl import DRLPolicyConfig
from pipeline.models.modeling_drl import SLOTS, DRLPolicy
from pipeline.world.protocol import Protocol


# ----------------------------------------------------------------------------- the policy inside SB3
class DRLFeatures(BaseFeaturesExtractor):
    """SB3's features extractor holding the whole `DRLPolicy`: out come [25 slot logits, value]."""

    def __init__(self, observation_space: spaces.Dict, config: dict[str, Any]):
        super().__init__(observation_space, features_dim=SLOTS + 1)
        self.policy = DRLPolicy(DRLPolicyConfig.from_dict(config))

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        one_hot = observations["robot"]  # SB3 one-hot encodes a Discrete observation
        robot = one_hot.reshape(one_hot.shape[0], -1).argmax(-1)
        logits, value = self.policy(
            observations["features"], observations["node_mask"], observations["neighbors"].long(), robot
        )
        return torch.cat([logits, value.unsqueeze(-1)], dim=-1)


class _SplitHeads(nn.Module):
    """SB3's "mlp extractor" slot: splits [logits, value] into the actor's and the critic's latents."""

    latent_dim_pi = SLOTS
    latent_dim_vf = 1

    def forward(self, latent: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        return self.forward_actor(latent), self.forward_critic(latent)

    def forward_actor(self, latent: torch.Tensor) -> torch.Tensor:
        return latent[:, :SLOTS]

    def forward_critic(self, latent: torch.Tensor) -> torch.Tensor:
        return latent[:, SLOTS:]


class DRLActorCritic(MaskableActorCriticPolicy):
    """MaskablePPO's actor-critic whose actor and critic are one `DRLPolicy` (no SB3 layers)."""

    def __init__(self, *args: Any, drl_config: dict[str, Any] | None = None, **kwargs: Any):
        kwargs.update(
            features_extractor_class=DRLFeatures,
            features_extractor_kwargs={"config": drl_config or {}},
            ortho_init=False,
            net_arch=[],
            share_features_extractor=True,
        )
        super().__init__(*args, **kwargs)

    def _build(self, lr_schedule: Callable[[float], float]) -> None:
        self.mlp_extractor = _SplitHeads()  # type: ignore[assignment]  # SB3 types it MlpExtractor; it needs only the forward_* heads
        self.action_net = nn.Identity()
        self.value_net = nn.Identity()  # type: ignore[assignment]  # SB3 types it Linear; any module mapping latents serves
        self.optimizer = self.optimizer_class(self.parameters(), lr=lr_schedule(1), **self.optimizer_kwargs)  # type: ignore[call-arg]  # SB3 types the class as the base Optimizer; its subclasses take lr

    @property
    def drl_policy(self) -> DRLPolicy:
        return cast(DRLFeatures, self.features_extractor).policy


# ----------------------------------------------------------------------------- settings
@config_dataclass
class PPOSettings:
    """MaskablePPO's settings (stable-baselines3's names and meanings)."""

    n_envs: Annotated[int, whole(1)] = 4  # environments stepped together; their maze sides cycle through maze_sides_m
    n_steps: Annotated[int, whole(1)] = 256  # steps per environment between updates
    batch_size: Annotated[int, whole(1)] = 128
    n_epochs: Annotated[int, whole(1)] = 4  # passes over each rollout
    learning_rate: Annotated[float, positive()] = 3e-4
    gamma: Annotated[float, fraction()] = 0.99
    gae_lambda: Annotated[float, fraction()] = 0.95
    clip_range: Annotated[float, positive()] = 0.2
    ent_coef: Annotated[float, real()] = 0.01
    vf_coef: Annotated[float, real()] = 0.5
    max_grad_norm: Annotated[float, positive()] = 0.5
    subprocess: Annotated[bool, flag()] = (
        False  # step the environments in worker processes (machines with cores to spare)
    )

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None, root: str = "ppo") -> "PPOSettings":
        """Build from params.yaml's `train_drl.ppo`; a refused value or an unknown key is a one-line
        ValueError naming it as `root.key`."""
        return validate(cls, values, root)

    def algorithm_kwargs(self) -> dict[str, Any]:
        values = asdict(self)
        for key in ("n_envs", "subprocess"):
            values.pop(key)
        return values

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@config_dataclass
class TrainingEnvironment:
    """The environments the agent learns in: generated mazes at the protocol, ARiADNE-style reward.
    Whether the protocol can make a maze of a side is the environment's (`ExploreEnv`) question."""

    # One per environment, round robin; one side alone may be given as a number. A tuple once made.
    maze_sides_m: Annotated[
        list[float] | float,
        any_of(
            list_of(positive("metres")), positive("metres"), description="a non-empty list of maze sides (m), each > 0"
        ),
    ] = (60.0, 80.0, 100.0)  # type: ignore[assignment]  # a tuple default, as the field is once made
    max_steps: Annotated[int, whole(1)] = 200  # actions before an episode is truncated
    area_weight: Annotated[float, real(0.0)] = 0.02  # reward per m^2 of newly observed free area
    distance_weight: Annotated[float, real(0.0)] = 0.1  # penalty per metre travelled
    completion_bonus: Annotated[float, real(0.0)] = 20.0  # reward on the step that completes the episode

    def __post_init__(self) -> None:
        sides = self.maze_sides_m if isinstance(self.maze_sides_m, (list, tuple)) else (self.maze_sides_m,)
        object.__setattr__(self, "maze_sides_m", tuple(float(side) for side in sides))

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None, root: str = "env") -> "TrainingEnvironment":
        """Build from params.yaml's `train_drl.env`; a refused value or an unknown key is a one-line
        ValueError naming it as `root.key`."""
        return validate(cls, values, root)

    def to_dict(self) -> dict[str, Any]:
        return {**asdict(self), "maze_sides_m": list(cast(tuple[float, ...], self.maze_sides_m))}

    def make(self, index: int, protocol: Protocol, policy: DRLPolicyConfig) -> ExploreEnv:
        """Environment `index`: mazes of its side, the policy's observation size, neighbour actions.
        A bad reward weight or maze side fails here with the environment's one-line ValueError."""
        return ExploreEnv(
            protocol=protocol,
            map="maze",
            maze_side_m=cast(tuple[float, ...], self.maze_sides_m)[
                index % len(cast(tuple[float, ...], self.maze_sides_m))
            ],
            action="neighbour",
            max_nodes=policy.max_nodes,
            max_neighbors=policy.max_neighbors,
            max_steps=self.max_steps,
            area_weight=self.area_weight,
            distance_weight=self.distance_weight,
            completion_bonus=self.completion_bonus,
        )


def vector_env(
    environment: TrainingEnvironment, protocol: Protocol, policy: DRLPolicyConfig, settings: PPOSettings, seed: int
) -> VecEnv:
    makers = cast(
        "list[Callable[[], Env]]",  # each called with no argument: its index is bound
        [(lambda i=i: environment.make(i, protocol, policy)) for i in range(settings.n_envs)],
    )
    envs = SubprocVecEnv(makers) if settings.subprocess else DummyVecEnv(makers)
    envs.seed(seed)
    return envs


# ----------------------------------------------------------------------------- progress and curves
class EpisodeLog(BaseCallback):
    """Collects each finished episode's return, distance, explored share and completion, and calls
    `on_rollout(row)` after each rollout with their means and PPO's losses."""

    def __init__(self, on_rollout: Callable[[dict[str, float]], None] | None = None):
        super().__init__()
        self.on_rollout = on_rollout
        self.rows: list[dict[str, float]] = []
        self._episodes: list[tuple[float, float, float, float]] = []
        self._returns: np.ndarray | None = None
        self._started = time.perf_counter()

    def _on_step(self) -> bool:
        rewards, dones, infos = self.locals["rewards"], self.locals["dones"], self.locals["infos"]
        if self._returns is None:
            self._returns = np.zeros(len(rewards))
        self._returns += rewards
        for i in np.flatnonzero(dones):
            info = infos[i]
            self._episodes.append(
                (
                    float(self._returns[i]),
                    float(info["distance"]),
                    float(info["explored_share"]),
                    float(info["complete"]),
                )
            )
            self._returns[i] = 0.0
        return True

    def _on_rollout_end(self) -> None:
        values = self.model.logger.name_to_value
        row: dict[str, float] = {
            "timesteps": float(self.num_timesteps),
            "seconds": time.perf_counter() - self._started,
            "episodes": float(len(self._episodes)),
        }
        if self._episodes:
            returns, distances, shares, complete = np.asarray(self._episodes).T
            row.update(
                episode_return=float(returns.mean()),
                episode_distance_m=float(distances.mean()),
                explored_share=float(shares.mean()),
                completed_share=float(complete.mean()),
            )
        for key in (
            "train/policy_gradient_loss",
            "train/value_loss",
            "train/entropy_loss",
            "train/approx_kl",
            "train/explained_variance",
        ):
            if key in values:
                row[key.split("/")[1]] = float(values[key])
        self._episodes.clear()
        self.rows.append(row)
        if self.on_rollout is not None:
            self.on_rollout(row)


def new_agent(
    envs: VecEnv, policy: DRLPolicyConfig, settings: PPOSettings, seed: int, device: str = "cpu"
) -> MaskablePPO:
    agent = MaskablePPO(
        DRLActorCritic,
        envs,
        policy_kwargs={"drl_config": policy.to_dict()},
        seed=seed,
        device=device,
        verbose=0,
        **settings.algorithm_kwargs(),
    )
    return with_silent_logger(agent)


def with_silent_logger(agent: MaskablePPO) -> MaskablePPO:
    """`agent` with a logger that writes nowhere: left to itself, SB3 makes an empty SB3-<date> folder in
    the temp directory at every `learn`. The rollout callback reads the logger's values in memory."""
    agent.set_logger(Logger(folder=None, output_formats=[]))
    return agent


def policy_of(agent: MaskablePPO) -> DRLPolicy:
    """The trained `DRLPolicy` inside an agent (shares its weights)."""
    return cast(DRLActorCritic, agent.policy).drl_policy


def evaluate(policy: DRLPolicy, envs: list[ExploreEnv], seeds: list[int]) -> list[dict[str, Any]]:
    """Greedy episodes of `policy` (the planner's decisions), one per (env, seed): distance, share, completion."""
    policy.eval()
    results = []
    for env, seed in zip(envs, seeds):
        observation, info = env.reset(seed=seed)
        done = False
        while not done:
            observation, _, terminated, truncated, info = env.step(policy.predict_action(observation))
            done = terminated or truncated
        results.append(
            {
                "map": info["map_name"],
                "distance": info["distance"],
                "explored_share": info["explored_share"],
                "complete": info["complete"],
                "steps": info["steps"],
            }
        )
    return results


def write_json(path: Path, payload: dict[str, Any]) -> None:
    atomic_write_text(path, json.dumps(payload, indent=2) + "\n")


def load_agent(path: Path, envs: VecEnv, device: str = "cpu") -> MaskablePPO:
    """An agent saved by `agent.save` (a checkpoint), attached to `envs` to continue training."""
    return with_silent_logger(MaskablePPO.load(path, env=envs, device=device))
