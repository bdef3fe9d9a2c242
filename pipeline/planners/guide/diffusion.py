"""The trained diffusion policy at decision time (Sec. IV-C): observe, sample, drive.

`PolicyOnGraph` keeps the last T_o observations of the global graph (each encoded once) and
samples `candidates` plans of T_p lattice steps with K denoising steps in one batched pass.
`drive` turns a sampled plan into moves the robot can make: each step becomes the lattice
neighbour it names when that edge is known free, else the known-free neighbour whose direction
best matches the policy's soft (expected) direction.
"""

from __future__ import annotations

import copy
import warnings
from dataclasses import replace
from pathlib import Path

import numpy as np
import torch
from diffusers import DDIMScheduler, DDPMScheduler

from pipeline.lattice.graph import LatticeGraph
from pipeline.models.defaults import cached_policy, resolve_policy_path
from pipeline.planners.guide.configuration_guide import GuideConfig
from pipeline.planners.options import check_int
from pipeline.prediction.global_graph import GlobalGraph
from pipeline.prediction.graph_observation import GraphObservation, observe


def warn_if_trained_at_other_taus(path, trained_on: dict, threshold: float, count_threshold: float | None) -> None:
    """A policy sees graphs built at its training observations' taus; others still run, but say so."""
    trained_tau = trained_on.get("threshold")
    if trained_tau is None:
        return
    trained_count = trained_on.get("count_threshold", trained_tau)  # older exports: one tau for both
    count = threshold if count_threshold is None else count_threshold
    if not (np.isclose(trained_tau, threshold) and np.isclose(trained_count, count)):
        warnings.warn(
            f"{path}: the policy was trained on graphs with predicted nodes at tau {trained_tau:g} "
            f"(utility count at {trained_count:g}); this planner builds them at {threshold:g} ({count:g})",
            stacklevel=4,
        )


def with_sampler(policy, sampler: str):
    """A shallow copy of `policy` (weights shared) that samples with another diffusers scheduler."""
    variant = copy.copy(policy)
    variant.config = replace(policy.config, sampler=sampler)
    scheduler_class = DDIMScheduler if sampler == "ddim" else DDPMScheduler
    variant.inference_scheduler = scheduler_class.from_config(policy.noise_scheduler.config)
    return variant


class PolicyOnGraph:
    """The diffusion policy a `guide` planner runs: loaded, checked against its options, and its
    observation history.

    The policy is the injected one, else `config.checkpoint`, else the pipeline's or the shipped
    policy of the config's variant. Options bounded by the loaded policy are checked here: K
    denoising steps pick K of its T training timesteps, T_a executed steps come from its T_p.
    """

    def __init__(self, config: GuideConfig, name: str, policy=None):
        self.trained_on: dict = {}
        self.path: Path | None = None
        if policy is None:
            path = resolve_policy_path(config.variant, config.checkpoint)
            policy, trained_on = cached_policy(path)
            variant = trained_on.get("variant")
            if variant is not None and variant != config.variant:
                raise ValueError(f"{path}: a {variant} policy (trained on {variant} observations); "
                                 f"{name} needs a {config.variant} policy")
            if config.predicts:
                warn_if_trained_at_other_taus(path, trained_on, config.threshold, config.count_threshold)
            self.trained_on, self.path, self.source = trained_on, path, str(path)
        else:
            self.source = "injected policy"
        policy_config = policy.config
        steps = policy_config.num_inference_steps if config.num_inference_steps is None else config.num_inference_steps
        check_int("num_inference_steps", steps, 1, policy_config.num_train_timesteps, note="the policy's num_train_timesteps")
        self.num_inference_steps = int(steps)
        if config.sampler is not None and config.sampler != policy_config.sampler:
            policy = with_sampler(policy, config.sampler)
        self.policy = policy
        steps = policy_config.action_steps if config.action_steps is None else config.action_steps
        check_int("action_steps", steps, 1, policy_config.horizon, note="the policy's horizon")
        self.action_steps = int(steps)
        self.candidates = int(config.candidates)

    @property
    def config(self):
        return self.policy.config

    def reset(self, seed: int) -> None:
        self.history: list[GraphObservation] = []
        self.encodings: list = []
        self.generator = torch.Generator().manual_seed(int(seed))

    def observe(self, global_graph: GlobalGraph, position) -> GraphObservation:
        """Add the global graph as the policy sees it (padded features, neighbours) to the last T_o."""
        obs = observe(global_graph, position, self.policy.config.max_neighbors)
        self.history.append(obs)
        self.encodings.append(None)
        del self.history[: -self.policy.config.obs_steps]
        del self.encodings[: -self.policy.config.obs_steps]
        return obs

    def encode(self, index: int):
        """z of history entry `index`, encoded once and kept (a graph is encoded for at most T_o decisions)."""
        if self.encodings[index] is None:
            o = self.history[index]
            with torch.inference_mode():
                self.encodings[index] = self.policy.encoder(
                    torch.from_numpy(o.features)[None], torch.from_numpy(o.node_mask)[None],
                    torch.from_numpy(o.neighbors.astype(np.int64))[None], torch.tensor([o.robot]),
                )
        return self.encodings[index]

    def sample(self) -> tuple[np.ndarray, np.ndarray]:
        """(C, T_p, 2) lattice steps and (C, T_p, 2) soft directions: `candidates` samples of K denoising
        steps each, conditioned on the last T_o observations, in one batched pass."""
        steps = self.policy.config.obs_steps
        picked = [max(0, len(self.history) - steps + k) for k in range(steps)]  # the first observation repeats
        obs_z = torch.stack([self.encode(i)[0] for i in picked])[None].expand(self.candidates, -1, -1)
        with torch.inference_mode():
            out = self.policy.predict_action(None, num_inference_steps=self.num_inference_steps, generator=self.generator,
                                             obs_z=obs_z)
        return out["deltas"].numpy(), out["expected"].numpy()


def attach_policy(planner, config: GuideConfig, name: str, policy=None) -> PolicyOnGraph:
    """The policy a `guide` planner (a `GlobalGraphPlanner`) runs, and what it fixes of that planner:
    its trained model is listed for the protocol check, and the global graph is built as the policy
    was trained on it (its max_nodes; the variant's region evaluation; every other field of a
    `global_graph=` option is kept)."""
    diffusion = PolicyOnGraph(config, name, policy)
    if diffusion.path is not None:
        planner.trained_models.append((str(diffusion.path), diffusion.trained_on.get("protocol")))
    planner.global_config = replace(planner.global_config, max_nodes=diffusion.config.max_nodes,
                                    use_region_evaluation=config.region_evaluation)
    return diffusion


def feasible_move(graph: LatticeGraph, node: int, step: np.ndarray, direction: np.ndarray) -> int | None:
    """The lattice node reached by `step` from `node` if that edge is known free, else the best-matching neighbour."""
    neighbours = graph.neighbours(node)
    if neighbours.size == 0:
        return None
    i, j = graph.node_ij[node]
    step = np.asarray(step, dtype=np.int64)
    if step.any():
        ti, tj = int(i + step[0]), int(j + step[1])
        target = [n for n in neighbours if graph.node_ij[n][0] == ti and graph.node_ij[n][1] == tj]
        if target:
            return int(target[0])
    want = np.asarray(direction, dtype=np.float64)
    if not step.any() and np.hypot(*want) < 0.25:
        return None  # the policy says stay: not a move
    if np.hypot(*want) < 1e-6:
        want = step.astype(np.float64)
    offsets = (graph.node_ij[neighbours] - graph.node_ij[node]).astype(np.float64)
    cosine = offsets @ want / (np.hypot(*offsets.T) * max(np.hypot(*want), 1e-9))
    length_gap = np.abs(np.hypot(*offsets.T) - np.hypot(*want))
    best = np.lexsort((neighbours, length_gap, -np.round(cosine, 6)))[0]
    return int(neighbours[best])


def drive(graph: LatticeGraph, robot: int, deltas: np.ndarray, expected: np.ndarray) -> list[list[int]]:
    """Each sampled plan driven on the known graph: its lattice nodes from `robot` (feasible moves only)."""
    paths = []
    for c in range(len(deltas)):
        path = [robot]
        for k in range(len(deltas[c])):
            nxt = feasible_move(graph, path[-1], deltas[c, k], expected[c, k])
            if nxt is None:
                break
            path.append(nxt)
        paths.append(path)
    return paths
