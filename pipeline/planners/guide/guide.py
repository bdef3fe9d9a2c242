"""GUIDE's planner as the paper runs it (Sec. IV-C): a diffusion policy on the global graph,
receding horizon.

At every decision (`plan`):

1. Environmental extraction (Sec. IV-A): fold the new scan into the lattice graph; the robot's
   node and the useful nodes it can reach (`locate`). Nothing reachable left: the episode ends.
2. Global graph inference (Sec. IV-B): predict the free nodes V_p in unknown space
   (Algorithm 1), keep those in regions of high score r(g) and boost utilities u(v)
   (`update_global_graph`); `guide_noregion` keeps every prediction, `dare` predicts nothing.
3. Observation: the global graph padded to the policy's node count, nearest nodes first, joins
   the history of the last T_o observations (`observe`).
4. Action: when the queue of actions is empty, the policy samples T_p lattice steps with K
   denoising steps, conditioned on those T_o observations (`sample_plans`: one call of the
   model's `predict_action`), and the first T_a of them are queued (`sample_plan`).
5. Receding horizon: the next queued step is executed, one waypoint per decision so that every
   intermediate position is observed, as in the expert data (`select_action`). After T_a steps
   the policy samples again.

Each sampled step becomes a move the motion rule allows (`feasible_move`); a step that is not
exactly the one sampled drops the rest of the queue (it assumed that step). A step that stays
put hands over to one step along the shortest path to the nearest useful node.

This object alone is the paper's planner (one sample per decision). Our additions wrap it
(`pipeline.planners.extensions`): several samples ranked by frontier per metre, the stall
hand-over, the tour vote; the registered `guide` combines them (`pipeline.planners.catalog`).
"""

from __future__ import annotations

import warnings
from collections import deque
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING, cast

import numpy as np
import torch

from pipeline.lattice.graph import LatticeGraph
from pipeline.models.defaults import cached_policy, resolve_policy_path
from pipeline.planners.guide.configuration_guide import GuideConfig
from pipeline.planners.predicting import GlobalGraphPlanner
from pipeline.prediction.graph_observation import GraphObservation, observe
from pipeline.prediction.node_predictor import InpaintFn
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.protocol import Protocol

if TYPE_CHECKING:
    from pipeline.models.modeling_diffusion import DiffusionPolicy

# (the planner, (C, T_p, 2) steps, (C, T_p, 2) directions) -> the index of the sampled plan to drive
PlanRanker = Callable[["GuidePlanner", np.ndarray, np.ndarray], int]


def within_policy(name: str, value: int, most: int, what: str) -> None:
    """ValueError unless the option `name` is in 1..`most`, a bound of the loaded policy (`what`):
    the config checks the option alone, this its fit to the policy."""
    if not 1 <= value <= most:
        raise ValueError(f"{name}: must be a whole number in 1..{most} ({what}), got {value}")


class GuidePlanner(GlobalGraphPlanner):
    """The diffusion policy on the region-evaluated global graph, receding horizon (Sec. IV-C).

    T_o (`obs_steps`) and T_p (`horizon`) are the trained policy's; T_a (`action_steps`) and K
    (`num_inference_steps`) default to what it was trained with. `candidates` plans are drawn
    per sampling (1, the paper's); with more, `plan_ranker` picks the one driven.
    """

    def __init__(
        self,
        config: GuideConfig = GuideConfig(),
        inpaint: InpaintFn | None = None,
        policy=None,
        candidates: int = 1,
        plan_ranker: PlanRanker | None = None,
    ):
        super().__init__(config, inpaint)
        self.policy, self.policy_source = self.load_policy(config, policy)
        model = self.policy.config
        self.obs_steps, self.horizon = int(model.obs_steps), int(model.horizon)  # T_o, T_p
        self.action_steps = int(model.action_steps if config.action_steps is None else config.action_steps)  # T_a
        within_policy("action_steps", self.action_steps, self.horizon, "the policy's horizon")
        steps = model.num_inference_steps if config.num_inference_steps is None else config.num_inference_steps
        within_policy("num_inference_steps", steps, model.num_train_timesteps, "the policy's num_train_timesteps")
        self.num_inference_steps = int(steps)  # K
        self.seed = config.seed
        self.candidates, self.plan_ranker = int(candidates), plan_ranker
        # The global graph as the policy was trained on it: its node count, the variant's region evaluation.
        self.global_config = replace(
            self.global_config, max_nodes=model.max_nodes, use_region_evaluation=config.region_evaluation
        )
        self.description = (
            f"{config.description} [policy {self.policy_source}; {self.predictor_source}; "
            f"{self.gate_source}; T_o={self.obs_steps} T_p={self.horizon} T_a={self.action_steps} "
            f"K={self.num_inference_steps}]"
        )

    def load_policy(self, config: GuideConfig, policy=None) -> tuple[DiffusionPolicy, str]:
        """(the policy, where it came from): the injected one, else `policy_file`, else the pipeline's
        or the shipped policy of the config's variant; its sampler as the config asks."""
        if policy is None:
            path = resolve_policy_path(config.variant, config.policy_file)
            policy, trained_on = cached_policy(path)
            variant = trained_on.get("variant")
            if variant is not None and variant != config.variant:
                raise ValueError(
                    f"{path}: a {variant} policy (trained on {variant} observations); "
                    f"{config.name or 'guide'} needs a {config.variant} policy"
                )
            if config.predicts:
                warn_if_trained_at_other_taus(path, trained_on, config.threshold, config.count_threshold)
            self.trained_models.append((str(path), trained_on.get("protocol")))
            source = str(path)
        else:
            source = "injected policy"
        if config.sampler is not None and config.sampler != policy.config.sampler:
            policy = policy.with_sampler(config.sampler)
        return policy, source

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        super().reset(frame, protocol, seed)
        self.history: deque[GraphObservation] = deque(maxlen=self.obs_steps)  # the last T_o observations
        self.encodings: deque = deque(maxlen=self.obs_steps)  # each one's encoding, made when first needed
        self.queue: deque[tuple[np.ndarray, np.ndarray]] = deque()  # (step, soft direction) of the T_a to execute
        self.generator = torch.Generator().manual_seed(int(seed if self.seed is None else self.seed))
        self.decisions = 0
        self.fallbacks = 0

    # ------------------------------------------------------------------ one decision
    def plan(self, observation: Observation) -> list[Waypoint]:
        if not self.perceive(observation):
            return []  # nothing reachable is left to explore
        return self.select_action()

    def perceive(self, observation: Observation) -> bool:
        """Steps 1-3: the lattice graph, the global graph and the policy's observation; False when
        no useful node is reachable (the episode is over)."""
        *_, useful = self.locate(observation)  # 1. the lattice graph (Sec. IV-A)
        if useful.size == 0:
            return False
        self.update_global_graph(observation)  # 2. predictions and region evaluation (Sec. IV-B)
        self.observe(observation.position)  # 3. the policy's observation, kept with the last T_o
        self.decisions += 1
        return True

    def observe(self, position) -> GraphObservation:
        """Add the global graph as the policy sees it (padded features, neighbours) to the last T_o."""
        obs = observe(self.global_graph, position, self.policy.config.max_neighbors)
        self.history.append(obs)
        self.encodings.append(None)
        return obs

    def select_action(self) -> list[Waypoint]:
        """Steps 4-5: the next of the queued T_a steps (sampling T_p anew when none is left), as a waypoint."""
        sampled = not self.queue
        if sampled:
            self.queue.extend(self.sample_plan())
        step, direction = self.queue.popleft()
        graph, robot = self.graph, self.robot
        assert graph is not None
        move = feasible_move(graph, robot, step, direction)
        if move is None or not np.array_equal(graph.node_ij[move] - graph.node_ij[robot], step):
            self.queue.clear()  # the rest of the chunk assumed this step: sample again next time
        if move is None:
            return self.hand_over(sampled)
        self.last_decision = {"fallback": False, "sampled": sampled, "fallback_share": self.fallbacks / self.decisions}
        return [cast(Waypoint, tuple(map(float, graph.node_world[move])))]

    def hand_over(self, sampled: bool = False) -> list[Waypoint]:
        """One step toward the nearest useful node instead of the policy's (the queue is dropped)."""
        self.fallbacks += 1
        self.queue.clear()
        waypoints = self.nearest_useful_step(self.robot)
        self.last_decision = {"fallback": True, "sampled": sampled, "fallback_share": self.fallbacks / self.decisions}
        return waypoints

    # ------------------------------------------------------------------ the policy
    def sample_plan(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The first T_a (step, soft direction) pairs of the plan to drive: the only sample, or the
        one `plan_ranker` picks."""
        deltas, expected = self.sample_plans()
        best = self.plan_ranker(self, deltas, expected) if self.candidates > 1 and self.plan_ranker is not None else 0
        return list(zip(deltas[best, : self.action_steps], expected[best, : self.action_steps]))

    def sample_plans(self) -> tuple[np.ndarray, np.ndarray]:
        """(C, T_p, 2) lattice steps and (C, T_p, 2) soft directions: `candidates` samples of K
        denoising steps each, conditioned on the last T_o observations, in one batched call."""
        picked = [max(0, len(self.history) - self.obs_steps + k) for k in range(self.obs_steps)]  # the first repeats
        obs_z = torch.stack([self.encoding(i)[0] for i in picked])[None].expand(self.candidates, -1, -1)
        out = self.policy.predict_action(obs_z, num_inference_steps=self.num_inference_steps, generator=self.generator)
        return out["deltas"].numpy(), out["expected"].numpy()

    def encoding(self, index: int) -> torch.Tensor:
        """z of history entry `index`, encoded once and kept (a graph is encoded for at most T_o decisions)."""
        if self.encodings[index] is None:
            self.encodings[index] = self.policy.encode(self.history[index])
        return self.encodings[index]


def warn_if_trained_at_other_taus(
    path: Path, trained_on: dict, threshold: float, count_threshold: float | None
) -> None:
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
            stacklevel=5,
        )


def feasible_move(graph: LatticeGraph, node: int, step: np.ndarray, direction: np.ndarray) -> int | None:
    """The lattice node reached by `step` from `node` if that edge is known free, else the
    best-matching known-free neighbour of the soft `direction`; None when the policy says stay."""
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
