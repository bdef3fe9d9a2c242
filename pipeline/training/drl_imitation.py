"""A warm start for the `drl` policy: imitate a planner's choices in `guide/Explore-v0`, then PPO.

Our addition, not Cao et al.'s (they train from scratch with soft actor-critic and a
ground-truth critic, for far longer than a CPU allows). A teacher planner (by default
`greedy_utility`) drives the environment; each of its decisions becomes the window slot it
chose, with the discounted return that followed. The policy's pointer learns the slots
(cross-entropy over the valid ones) and its value head the returns, so that PPO starts from a
sensible actor and a critic that already knows the scale of the returns: a value head left at
random would make PPO's first advantages noise and undo the actor. `episodes: 0` skips it.
"""

from __future__ import annotations

from dataclasses import asdict
from typing import Annotated, Any, Callable

import numpy as np
import torch
import torch.nn.functional as F
from tqdm.auto import tqdm

from pipeline.common.config import config_dataclass, positive, real, satisfies, text, validate, whole
from pipeline.models.modeling_drl import MASKED_LOGIT, DRLPolicy
from pipeline.planners import make_planner, planner_config
from pipeline.world.planner import reset_planner

OBSERVATION_KEYS = ("features", "node_mask", "neighbors", "robot", "action_mask")


@config_dataclass
class ImitationSettings:
    """The warm start's teacher and its training."""

    # The teacher: a registered planner that moves one window step per decision.
    planner: Annotated[str, satisfies(planner_config, "a registered planner", kind=text())] = "greedy_utility"
    episodes: Annotated[int, whole(0)] = (
        0  # teacher episodes to learn from (0: no warm start, PPO from the guidepost prior)
    )
    epochs: Annotated[int, whole(1)] = 4  # passes over the teacher's decisions
    batch_size: Annotated[int, whole(1)] = 128
    learning_rate: Annotated[float, positive()] = 0.001  # Adam
    dagger_rounds: Annotated[int, whole(0)] = (
        2  # rounds in which the policy drives and the teacher labels every state it visits
    )
    dagger_episodes: Annotated[int, whole(1)] = 100  # episodes per round
    dagger_epochs: Annotated[int, whole(1)] = 4  # passes over all decisions gathered so far after each round
    # Weight of the value regression (squared error of returns of tens) beside the cross-entropy.
    value_weight: Annotated[float, real(0.0)] = 0.02

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None, root: str = "imitation") -> "ImitationSettings":
        """Build from params.yaml's `train_drl.imitation`; a refused value or an unknown key is a
        one-line ValueError naming it as `root.key`."""
        return validate(cls, values, root)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def teacher_decisions(
    make_env: Callable[[int], Any],
    teacher_name: str,
    episodes: int,
    gamma: float,
    seed: int,
    student: DRLPolicy | None = None,
) -> tuple[dict[str, np.ndarray], dict[str, float]]:
    """The teacher's choices in `episodes` episodes (episode i in environment `make_env(i % 4)`,
    reset with seed + i): stacked observations, the slot the teacher chose and the discounted
    return from there; with the mean distance and completed share of the episodes. The teacher
    drives, or with `student` the student drives greedily (DAgger) while the teacher still
    says, at every state the student reaches, what it would do there."""
    columns: dict[str, list] = {key: [] for key in (*OBSERVATION_KEYS, "action", "return")}
    envs: dict[int, Any] = {}
    distances, completed = [], []
    who = "student drives" if student is not None else "teacher drives"
    for i in tqdm(range(episodes), desc=f"imitation: {who}", unit="episode", mininterval=2.0):
        if i % 4 not in envs:
            envs[i % 4] = make_env(i % 4)
        env = envs[i % 4]
        observation, info = env.reset(seed=seed + i)
        teacher = make_planner(teacher_name)
        reset_planner(teacher, env.ground_truth, env.episode.protocol, seed + i)
        rewards = []
        done = False
        while not done:
            waypoints = teacher.plan(env.episode.observe())
            if not waypoints:
                break
            try:
                action = env.action_for_waypoint(waypoints[0])
            except ValueError:
                action = -1
            if action < 0 or not observation["action_mask"][action]:
                raise ValueError(
                    f"imitation.planner {teacher_name!r} moved outside the robot's known window edges; "
                    "the teacher must step to a window neighbour per decision (as greedy_utility does)"
                )
            for key in OBSERVATION_KEYS:
                columns[key].append(np.asarray(observation[key]))
            columns["action"].append(action)
            if student is not None:
                action = student.predict_action(observation)
            observation, reward, terminated, truncated, info = env.step(action)
            rewards.append(reward)
            done = terminated or truncated
        running = 0.0
        returns = []
        for reward in reversed(rewards):
            running = reward + gamma * running
            returns.append(running)
        columns["return"].extend(reversed(returns))
        distances.append(info["distance"])
        completed.append(bool(info["complete"]))
    for env in envs.values():
        env.close()
    samples = {key: np.stack(values) for key, values in columns.items()} if columns["action"] else {}
    return samples, {
        "distance_m": float(np.mean(distances)),
        "completed": float(np.mean(completed)),
        "decisions": float(len(columns["action"])),
    }


def imitate(
    policy: DRLPolicy, samples: dict[str, np.ndarray], settings: ImitationSettings, seed: int, epochs: int | None = None
) -> list[dict[str, float]]:
    """Train `policy` in place on the teacher's decisions; per epoch: loss, slot agreement, value error."""
    generator = torch.Generator().manual_seed(seed)
    tensors = {key: torch.as_tensor(value) for key, value in samples.items()}
    count = len(tensors["action"])
    optimizer = torch.optim.Adam(policy.parameters(), lr=settings.learning_rate)
    history = []
    policy.train()
    for epoch in range(1, (epochs or settings.epochs) + 1):
        order = torch.randperm(count, generator=generator)
        totals = np.zeros(3)
        for start in tqdm(
            range(0, count, settings.batch_size),
            desc=f"imitation: epoch {epoch}",
            unit="batch",
            mininterval=2.0,
            leave=False,
        ):
            index = order[start : start + settings.batch_size]
            logits, value = policy(
                tensors["features"][index],
                tensors["node_mask"][index],
                tensors["neighbors"][index].long(),
                tensors["robot"][index].long(),
            )
            logits = torch.where(tensors["action_mask"][index].bool(), logits, torch.full_like(logits, MASKED_LOGIT))
            target, returns = tensors["action"][index].long(), tensors["return"][index].float()
            action_loss = F.cross_entropy(logits, target)
            value_loss = F.mse_loss(value, returns)
            loss = action_loss + settings.value_weight * value_loss
            optimizer.zero_grad()
            loss.backward()
            torch.nn.utils.clip_grad_norm_(policy.parameters(), 1.0)
            optimizer.step()
            totals += np.array(
                [loss.item(), (logits.argmax(-1) == target).float().sum().item(), (value - returns).abs().sum().item()]
            ) * np.array([len(index), 1, 1])
        history.append(
            {
                "epoch": float(epoch),
                "loss": totals[0] / count,
                "agreement": totals[1] / count,
                "value_error": totals[2] / count,
            }
        )
    policy.eval()
    return history


def warm_start(
    policy: DRLPolicy, make_env: Callable[[int], Any], settings: ImitationSettings, gamma: float, seed: int
) -> dict[str, Any]:
    """Imitation, then `dagger_rounds` DAgger rounds, on `policy` in place; what each phase measured
    (the drivers' distance and completion, the agreement with the teacher per epoch)."""
    samples, driven = teacher_decisions(make_env, settings.planner, settings.episodes, gamma, seed)
    phases = [{"phase": "teacher", **driven, "epochs": imitate(policy, samples, settings, seed)}]
    for round_index in range(1, settings.dagger_rounds + 1):
        round_seed = seed + round_index * 100_003  # other mazes each round
        more, driven = teacher_decisions(
            make_env, settings.planner, settings.dagger_episodes, gamma, round_seed, student=policy
        )
        samples = {key: np.concatenate([samples[key], more[key]]) for key in samples}
        phases.append(
            {
                "phase": f"dagger {round_index}",
                **driven,
                "epochs": imitate(policy, samples, settings, round_seed, settings.dagger_epochs),
            }
        )
    return {"decisions": int(len(samples["action"])), "phases": phases}
