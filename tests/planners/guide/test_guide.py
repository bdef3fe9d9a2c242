"""The paper's receding-horizon loop (Sec. IV-C) in `GuidePlanner`: T_a of each T_p sample are
executed before the next sampling, the policy sees the last T_o observations, K denoising steps
run per sampling, a seed repeats the plans, and `guide:mode=policy` reduced to the paper's
options drives exactly this object."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pipeline.models.configuration_diffusion import DiffusionPolicyConfig
from pipeline.models.modeling_diffusion import DiffusionPolicy
from pipeline.planners import make_planner
from pipeline.planners.guide.configuration_guide import GuideConfig
from pipeline.planners.guide.guide import GuidePlanner
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode

PROTOCOL = Protocol(max_steps=60)
T_O, T_P, T_A, K = 3, 6, 3, 4


def blank(image):
    return np.zeros(np.shape(image), np.float32)  # nothing predicted: the observed graph


class CountingPolicy(DiffusionPolicy):
    """A small untrained policy that records each sampling's conditioning and denoiser calls."""

    def __init__(self):
        torch.manual_seed(0)
        super().__init__(
            DiffusionPolicyConfig(
                max_nodes=48,
                d_model=16,
                heads=2,
                encoder_layers=1,
                denoiser_layers=1,
                horizon=T_P,
                obs_steps=T_O,
                action_steps=2,
                num_inference_steps=10,
            )
        )
        self.eval()
        self.conditionings: list[torch.Tensor] = []
        self.denoiser_calls: list[int] = []
        self.plans: list[np.ndarray] = []
        denoise = self.noise_net.denoise

        def counted(x, memory):
            self.denoiser_calls[-1] += 1
            return denoise(x, memory)

        self.noise_net.denoise = counted

    def predict_action(self, obs, num_inference_steps=None, generator=None):
        self.conditionings.append(obs.clone())
        self.denoiser_calls.append(0)
        out = super().predict_action(obs, num_inference_steps=num_inference_steps, generator=generator)
        self.plans.append(out["deltas"].numpy().copy())
        return out


def paper_planner(policy=None, **options) -> GuidePlanner:
    config = GuideConfig(action_steps=T_A, num_inference_steps=K, **options)
    return GuidePlanner(config, inpaint=blank, policy=policy or CountingPolicy())


def drive(planner, maze, seed: int = 0):
    """Run an episode, recording after each decision: (sampled, the robot's lattice step)."""
    record = []
    original = planner.plan

    def plan(observation):
        waypoints = original(observation)
        if waypoints:
            graph = planner.graph
            step = graph.node_ij[graph.nearest_node(waypoints[0])] - graph.node_ij[planner.robot]
            record.append((planner.last_decision["sampled"], planner.last_decision["fallback"], step))
        return waypoints

    planner.plan = plan
    result = run_episode(maze, planner, PROTOCOL, seed=seed)
    return result, record


def test_the_first_t_a_steps_of_each_sample_are_executed_before_the_next_sampling(small_maze):
    planner = paper_planner()
    _, record = drive(planner, small_maze)
    plans = planner.policy.plans
    assert len(plans) >= 3
    sampling = [i for i, (sampled, _, _) in enumerate(record) if sampled]
    assert len(sampling) == len(plans)  # one call of the policy per sampling
    chunks = 0
    for number, start in enumerate(sampling):
        end = sampling[number + 1] if number + 1 < len(sampling) else len(record)
        assert 1 <= end - start <= T_A  # never more than T_a decisions from one sample
        planned = plans[number][0]  # the single sample's T_p steps
        for k in range(start, end):
            _, fallback, step = record[k]
            if fallback:
                break
            if not np.array_equal(step, planned[k - start]):
                assert k == end - 1  # a step other than the planned one ends the chunk: sample again
        chunks += end - start == T_A
    assert chunks >= 1  # whole chunks of T_a steps happen


def test_the_policy_sees_the_last_t_o_observations(small_maze):
    planner = paper_planner()
    planner.reset(small_maze, PROTOCOL, 0)
    seen = []
    original = planner.observe

    def observe(position):
        obs = original(position)
        seen.append(obs)
        return obs

    planner.observe = observe
    result = run_episode(small_maze, planner, PROTOCOL, seed=0)
    assert result.trajectory
    assert len(planner.history) == T_O
    assert [id(o) for o in planner.history] == [id(o) for o in seen[-T_O:]]
    # Each sampling is conditioned on the encodings of the last T_o observations (the first repeated early on).
    policy = planner.policy
    first = policy.conditionings[0]
    assert first.shape == (1, T_O, policy.config.d_model)
    assert torch.equal(first[0, 0], first[0, -1])  # one observation so far: repeated T_o times
    last_encodings = torch.stack([planner.encoding(i)[0] for i in range(T_O)])
    if planner.last_decision["sampled"]:
        assert torch.equal(policy.conditionings[-1][0], last_encodings)


def test_k_denoising_steps_run_per_sampling(small_maze):
    planner = paper_planner()
    drive(planner, small_maze)
    calls = planner.policy.denoiser_calls
    assert calls and set(calls) == {K}


def test_a_seed_gives_the_same_plans_and_another_seed_other_plans(small_maze):
    policy = CountingPolicy()
    first, _ = drive(paper_planner(policy, seed=5), small_maze)
    plans = [p.copy() for p in policy.plans]
    policy.plans.clear()
    again, _ = drive(paper_planner(policy, seed=5), small_maze, seed=9)  # the option wins over the episode's seed
    assert again.trajectory == first.trajectory
    assert all(np.array_equal(a, b) for a, b in zip(plans, policy.plans))
    policy.plans.clear()
    drive(paper_planner(policy, seed=6), small_maze)
    assert not all(np.array_equal(a, b) for a, b in zip(plans, policy.plans))


def test_guide_mode_policy_with_the_papers_options_is_this_object_driving(small_maze):
    policy = CountingPolicy()
    paper = run_episode(small_maze, paper_planner(policy), PROTOCOL, seed=3)
    registered = make_planner(
        "guide",
        mode="policy",
        candidates=1,
        stall_steps=10**6,
        sliver_gate=False,
        action_steps=T_A,
        num_inference_steps=K,
        inpaint=blank,
        policy=policy,
    )
    driven = run_episode(small_maze, registered, PROTOCOL, seed=3)
    assert driven.trajectory == paper.trajectory
    assert len(paper.trajectory) > 5


def test_the_config_holds_the_papers_options_only():
    names = [option.name for option in GuideConfig.options()]
    assert len(names) <= 12
    assert {
        "policy_file",
        "inpainter_file",
        "threshold",
        "count_threshold",
        "global_graph",
        "action_steps",
        "num_inference_steps",
        "seed",
    } <= set(names)
    assert not {"candidates", "stall_steps", "prior_weight", "lookahead", "mode", "sliver_gate"} & set(names)


@pytest.mark.parametrize("old,new", [("checkpoint", "policy_file"), ("inpainter_checkpoint", "inpainter_file")])
def test_old_option_names_still_work_for_one_release_with_a_warning(old, new):
    from pipeline.models.defaults import SHIPPED_INPAINTER, SHIPPED_POLICY

    path = str(SHIPPED_POLICY["guide"] if new == "policy_file" else SHIPPED_INPAINTER)
    with pytest.warns(FutureWarning, match=f"option {old} is now {new}"):
        planner = make_planner("guide", **{old: path})
    assert getattr(planner.config, new) == path
