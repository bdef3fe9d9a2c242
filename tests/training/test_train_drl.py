"""MaskablePPO glue of the drl policy (pipeline/training/drl.py): settings checks, a tiny agent that
learns, its greedy choice is the exported policy's, the weights are shared, the episode log, the
greedy evaluation, and saving and loading an agent."""

from __future__ import annotations

import tempfile
from types import SimpleNamespace

import numpy as np
import pytest
import torch

from pipeline.models.configuration_drl import DRLPolicyConfig
from pipeline.models.modeling_drl import MASKED_LOGIT, SLOTS
from pipeline.planners import make_planner
from pipeline.training.drl import (
    DRLActorCritic,
    DRLFeatures,
    EpisodeLog,
    PPOSettings,
    TrainingEnvironment,
    evaluate,
    load_agent,
    new_agent,
    policy_of,
    vector_env,
)
from pipeline.training.drl_imitation import ImitationSettings
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode

POLICY = DRLPolicyConfig(max_nodes=32, d_model=16, heads=2, encoder_layers=1)
SETTINGS = PPOSettings(n_envs=2, n_steps=32, batch_size=32, n_epochs=1)
ENVIRONMENT = TrainingEnvironment(maze_sides_m=(50,), max_steps=30)
PROTOCOL = Protocol()


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"n_envs": 0}, "ppo.n_envs: must be a whole number >= 1, got 0"),
        ({"n_steps": 32.0}, "ppo.n_steps: must be a whole number >= 1, got 32.0"),
        ({"batch_size": True}, "ppo.batch_size: must be a whole number >= 1, got True"),
        ({"n_epochs": -1}, "ppo.n_epochs: must be a whole number >= 1, got -1"),
        ({"learning_rate": 0.0}, "ppo.learning_rate: must be a finite number > 0, got 0.0"),
        ({"learning_rate": float("nan")}, "ppo.learning_rate: must be a finite number > 0, got nan"),
        ({"gamma": 1.5}, "ppo.gamma: must be a number in [0, 1], got 1.5"),
        ({"gae_lambda": -0.1}, "ppo.gae_lambda: must be a number in [0, 1], got -0.1"),
        ({"clip_range": 0}, "ppo.clip_range: must be a finite number > 0, got 0"),
        ({"ent_coef": float("inf")}, "ppo.ent_coef: must be a finite number, got inf"),
        ({"vf_coef": "half"}, "ppo.vf_coef: must be a finite number, got 'half'"),
        ({"max_grad_norm": -1.0}, "ppo.max_grad_norm: must be a finite number > 0, got -1.0"),
        ({"subprocess": "yes"}, "ppo.subprocess: must be true or false, got 'yes'"),
        (
            {"lr": 0.001},
            "ppo.lr: unknown setting (known: n_envs, n_steps, batch_size, n_epochs, learning_rate, gamma, "
            "gae_lambda, clip_range, ent_coef, vf_coef, max_grad_norm, subprocess), got 0.001",
        ),
    ],
)
def test_ppo_settings_refuse_bad_values(values, message):
    with pytest.raises(ValueError) as refused:
        PPOSettings.from_dict(values)
    assert str(refused.value) == message


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"planner": "nope"}, "imitation.planner: must be a registered planner (unknown planner 'nope'; choose from: "),
        ({"planner": 3}, "imitation.planner: must be a non-empty string, got 3"),
        ({"episodes": -1}, "imitation.episodes: must be a whole number >= 0, got -1"),
        ({"epochs": 0}, "imitation.epochs: must be a whole number >= 1, got 0"),
        ({"learning_rate": 0}, "imitation.learning_rate: must be a finite number > 0, got 0"),
        ({"value_weight": -0.5}, "imitation.value_weight: must be a finite number >= 0, got -0.5"),
        ({"teacher": "guide"}, "imitation.teacher: unknown setting (known: planner, episodes, "),
    ],
)
def test_imitation_settings_refuse_bad_values(values, message):
    with pytest.raises(ValueError) as refused:
        ImitationSettings.from_dict(values)
    assert str(refused.value).startswith(message), str(refused.value)


def test_imitation_settings_round_trip_through_their_dict():
    settings = ImitationSettings.from_dict({"planner": "nearest_frontier", "episodes": 3, "learning_rate": 1})
    assert settings.learning_rate == 1.0 and ImitationSettings.from_dict(settings.to_dict()) == settings


def test_ppo_settings_pass_sb3_its_own_arguments():
    settings = PPOSettings.from_dict({"n_envs": 3, "n_steps": 16, "ent_coef": 0, "subprocess": True})
    kwargs = settings.algorithm_kwargs()
    assert "n_envs" not in kwargs and "subprocess" not in kwargs
    assert kwargs["n_steps"] == 16 and kwargs["ent_coef"] == 0 and kwargs["learning_rate"] == 3e-4
    assert PPOSettings.from_dict(settings.to_dict()) == settings


SIDES = "env.maze_sides_m: must be a non-empty list of maze sides (m), each > 0, got "


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"maze_sides_m": []}, SIDES + "[]"),
        ({"maze_sides_m": [50, -5]}, SIDES + "[50, -5]"),
        ({"maze_sides_m": "50"}, SIDES + "'50'"),
        ({"maze_sides_m": [True]}, SIDES + "[True]"),
        ({"maze_sides_m": [float("nan")]}, SIDES + "[nan]"),
        ({"max_steps": 0}, "env.max_steps: must be a whole number >= 1, got 0"),
        ({"max_steps": 20.5}, "env.max_steps: must be a whole number >= 1, got 20.5"),
        ({"area_weight": "much"}, "env.area_weight: must be a finite number >= 0, got 'much'"),
        ({"area_weight": -1.0}, "env.area_weight: must be a finite number >= 0, got -1.0"),
        ({"distance_weight": float("nan")}, "env.distance_weight: must be a finite number >= 0, got nan"),
        ({"completion_bonus": -20}, "env.completion_bonus: must be a finite number >= 0, got -20"),
        (
            {"max_step": 20},
            "env.max_step: unknown setting (known: maze_sides_m, max_steps, area_weight, distance_weight, "
            "completion_bonus), got 20",
        ),
    ],
)
def test_training_environment_refuses_bad_values(values, message):
    with pytest.raises(ValueError) as refused:
        TrainingEnvironment.from_dict(values)
    assert str(refused.value) == message


def test_training_environment_makes_the_policys_environments():
    environment = TrainingEnvironment.from_dict({"maze_sides_m": [50, 60], "max_steps": 12, "area_weight": 0.5})
    assert environment.maze_sides_m == (50.0, 60.0) and environment.to_dict()["maze_sides_m"] == [50.0, 60.0]
    assert TrainingEnvironment(maze_sides_m=70).maze_sides_m == (70.0,)
    assert TrainingEnvironment.from_dict(environment.to_dict()) == environment
    configs = [environment.make(i, PROTOCOL, POLICY).config for i in range(3)]
    assert [c.maze_side_m for c in configs] == [50.0, 60.0, 50.0]  # round robin
    assert all(
        c.map == "maze"
        and c.action == "neighbour"
        and c.max_nodes == 32
        and c.max_neighbors == 25
        and c.max_steps == 12
        and c.area_weight == 0.5
        for c in configs
    )
    # A maze side the protocol cannot make fails when the environment is made, naming the parameter.
    with pytest.raises(ValueError, match="maze_side_m 52"):
        TrainingEnvironment(maze_sides_m=(52,)).make(0, PROTOCOL, POLICY)


@pytest.fixture(scope="module")
def trained():
    """A tiny agent after 64 steps: (agent, its episode log, the rows handed to on_rollout, the
    weights it started from)."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)
    envs = vector_env(ENVIRONMENT, PROTOCOL, POLICY, SETTINGS, seed=3)
    agent = new_agent(envs, POLICY, SETTINGS, seed=3)
    initial = {k: v.clone() for k, v in policy_of(agent).state_dict().items()}
    handed: list[dict] = []
    log = EpisodeLog(handed.append)
    agent.learn(64, callback=log)
    yield agent, log, handed, initial
    envs.close()
    torch.set_num_threads(previous)


def test_the_agent_learns_64_steps(trained):
    agent, _, _, initial = trained
    assert agent.num_timesteps == 64
    assert isinstance(agent.policy, DRLActorCritic) and isinstance(agent.policy.features_extractor, DRLFeatures)
    learned = policy_of(agent).state_dict()
    changed = [k for k in initial if not torch.equal(initial[k], learned[k])]
    assert "guidepost_weight" in changed and "key.weight" in changed and "value_head.2.weight" in changed


def test_every_weight_trained_is_the_exported_policys(trained):
    agent, _, _, _ = trained
    policy = policy_of(agent)
    assert policy is agent.policy.drl_policy
    exported = {id(p) for p in policy.parameters()}
    assert {id(p) for p in agent.policy.parameters()} == exported  # no SB3 layers beside it
    optimised = {id(p) for group in agent.policy.optimizer.param_groups for p in group["params"]}
    assert optimised == exported


def test_the_policy_shares_the_agents_weights(trained):
    agent, _, _, _ = trained
    policy = policy_of(agent)
    env = ENVIRONMENT.make(0, PROTOCOL, POLICY)
    obs, _ = env.reset(seed=11)
    tensor_obs, _ = agent.policy.obs_to_tensor(obs)
    with torch.no_grad():
        before = agent.policy.get_distribution(tensor_obs).distribution.logits.clone()
        saved = policy.key.weight.clone()
        try:
            policy.key.weight.mul_(-3.0)  # a change made through the exported policy...
            after = agent.policy.get_distribution(tensor_obs).distribution.logits
        finally:
            policy.key.weight.copy_(saved)
    assert not torch.allclose(before, after)  # ...is the agent's
    with torch.no_grad():
        restored = agent.policy.get_distribution(tensor_obs).distribution.logits
    torch.testing.assert_close(restored, before)
    env.close()


def test_the_agents_greedy_action_is_the_policys(trained):
    agent, _, _, _ = trained
    policy = policy_of(agent)
    env = ENVIRONMENT.make(0, PROTOCOL, POLICY)
    compared = 0
    for seed in (21, 22):
        obs, _ = env.reset(seed=seed)
        done = False
        while not done:
            mask = env.action_masks()
            np.testing.assert_array_equal(mask, obs["action_mask"].astype(bool))
            action = policy.predict_action(obs)
            chosen, _ = agent.predict(obs, action_masks=mask, deterministic=True)
            assert int(chosen) == action
            # The agent's masked distribution is the policy's logits, masked and normalised.
            tensor_obs, _ = agent.policy.obs_to_tensor(obs)
            with torch.no_grad():
                distribution = agent.policy.get_distribution(tensor_obs, action_masks=mask[None])
                features = agent.policy.extract_features(tensor_obs)
                logits, value = policy(
                    torch.as_tensor(obs["features"])[None],
                    torch.as_tensor(obs["node_mask"])[None].bool(),
                    torch.as_tensor(obs["neighbors"])[None].long(),
                    torch.as_tensor([int(obs["robot"])]),
                )
            assert features.shape == (1, SLOTS + 1)
            torch.testing.assert_close(features[:, :SLOTS], logits, rtol=1e-5, atol=1e-4)
            torch.testing.assert_close(agent.policy.predict_values(tensor_obs)[:, 0], value, rtol=1e-5, atol=1e-5)
            masked = torch.where(torch.as_tensor(mask)[None], logits, torch.full_like(logits, MASKED_LOGIT))
            allowed = torch.as_tensor(mask)
            torch.testing.assert_close(
                distribution.distribution.logits[0, allowed],
                torch.log_softmax(masked, -1)[0, allowed],
                rtol=1e-4,
                atol=1e-4,
            )
            obs, _, terminated, truncated, info = env.step(action)
            assert not info["invalid_action"]
            done = terminated or truncated
            compared += 1
    env.close()
    assert compared >= 10


def test_the_episode_log_records_rollouts(trained):
    _, log, handed, _ = trained
    assert len(log.rows) == 1 and handed == log.rows  # one rollout of 2 x 32 steps
    row = log.rows[0]
    assert row["timesteps"] == 64.0 and row["seconds"] > 0
    # 2 environments x 32 steps with episodes of at most 30 actions: each finished one at least.
    assert row["episodes"] >= 2
    assert {"episode_return", "episode_distance_m", "explored_share", "completed_share"} <= set(row)
    assert 0.0 < row["explored_share"] <= 1.0 and 0.0 <= row["completed_share"] <= 1.0
    assert row["episode_distance_m"] > 0


def test_the_episode_log_sums_returns_per_environment():
    """Rewards add up per environment until its episode ends; a rollout's row is their means."""
    logger = SimpleNamespace(name_to_value={"train/value_loss": 0.5})
    log = EpisodeLog()
    log.model, log.num_timesteps = SimpleNamespace(logger=logger), 6
    infos = [
        {"distance": 10.0, "explored_share": 0.5, "complete": False},
        {"distance": 30.0, "explored_share": 1.0, "complete": True},
    ]
    for rewards, dones in (([1.0, 2.0], [False, False]), ([3.0, 4.0], [True, False]), ([5.0, 6.0], [True, True])):
        log.locals = {"rewards": np.array(rewards), "dones": np.array(dones), "infos": infos}
        log._on_step()
    log._on_rollout_end()
    (row,) = log.rows
    assert row["episodes"] == 3 and row["timesteps"] == 6
    assert row["episode_return"] == pytest.approx((1.0 + 3.0 + 5.0 + 2.0 + 4.0 + 6.0) / 3)  # 4, 5 and 12
    assert row["episode_distance_m"] == pytest.approx(50.0 / 3) and row["completed_share"] == pytest.approx(1 / 3)
    assert row["value_loss"] == 0.5
    log._on_rollout_end()  # no episode finished since: no episode means
    assert log.rows[1]["episodes"] == 0 and "episode_return" not in log.rows[1]


def test_vector_envs_are_seeded():
    first = vector_env(ENVIRONMENT, PROTOCOL, POLICY, SETTINGS, seed=5)
    again = vector_env(ENVIRONMENT, PROTOCOL, POLICY, SETTINGS, seed=5)
    other = vector_env(ENVIRONMENT, PROTOCOL, POLICY, SETTINGS, seed=6)
    try:
        a, b, c = first.reset(), again.reset(), other.reset()
        assert first.num_envs == 2
        np.testing.assert_array_equal(a["features"], b["features"])
        assert not np.array_equal(a["features"], c["features"])
        assert not np.array_equal(a["features"][0], a["features"][1])  # each environment its own maze
    finally:
        for envs in (first, again, other):
            envs.close()


def test_evaluate_is_the_planners_episode(trained):
    """evaluate's greedy episodes are the drl planner's under run_episode on the same maze."""
    protocol = Protocol(max_steps=40)
    policy = policy_of(trained[0])
    env = TrainingEnvironment(maze_sides_m=(50,), max_steps=protocol.max_steps).make(0, protocol, POLICY)
    with pytest.raises(RuntimeError, match="reset"):
        _ = env.ground_truth
    results = evaluate(policy, [env, env], [4800, 4801])
    assert [sorted(r) for r in results] == [["complete", "distance", "explored_share", "map", "steps"]] * 2
    assert results[0]["map"] != results[1]["map"]
    assert evaluate(policy, [env], [4801])[0] == results[1]
    for seed, result in zip((4800, 4801), results):
        env.reset(seed=seed)
        reference = run_episode(env.ground_truth, make_planner("drl", policy=policy, stall_steps=0), protocol)
        assert reference.distance_m == pytest.approx(result["distance"], abs=1e-9)
        assert reference.complete == result["complete"]
    env.close()


def test_a_saved_agent_loads_and_trains_on(trained, tmp_path, monkeypatch):
    agent, _, _, _ = trained
    agent.save(tmp_path / "last.zip")
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))  # where SB3's own logger would write
    envs = vector_env(ENVIRONMENT, PROTOCOL, POLICY, SETTINGS, seed=9)
    try:
        loaded = load_agent(tmp_path / "last.zip", envs)
        assert loaded.num_timesteps == 64 and isinstance(loaded.policy, DRLActorCritic)
        assert policy_of(loaded).config == POLICY
        for name, value in policy_of(agent).state_dict().items():
            assert torch.equal(value, policy_of(loaded).state_dict()[name]), name
        loaded.learn(64, reset_num_timesteps=False)
        assert loaded.num_timesteps == 128
        assert not list(tmp_path.glob("SB3-*"))  # no empty log folder left in the temp directory
    finally:
        envs.close()


def test_a_new_agent_leaves_no_log_folder(tmp_path, monkeypatch):
    monkeypatch.setattr(tempfile, "tempdir", str(tmp_path))
    envs = vector_env(ENVIRONMENT, PROTOCOL, POLICY, SETTINGS, seed=4)
    try:
        agent = new_agent(envs, POLICY, SETTINGS, seed=4)
        rows: list[dict] = []
        agent.learn(64, callback=EpisodeLog(rows.append))
        assert len(rows) == 1 and not list(tmp_path.glob("SB3-*"))
    finally:
        envs.close()
