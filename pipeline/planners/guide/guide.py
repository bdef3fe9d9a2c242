"""The diffusion planners: `guide`, its ablation `guide_noregion`, and the DARE baseline `dare`.

Every decision: update the lattice graph, predict V_p (GUIDE only), build the global
graph (region-evaluated, or keeping every prediction for `guide_noregion`, or the observed
graph alone for `dare`), make the padded observation, stack the last T_o observations, and
sample T_p lattice steps with K denoising steps for `candidates` noise draws in one batched
pass. The first T_a steps are executed (receding horizon), one waypoint per simulator call
so that every intermediate position is observed, as in the expert data.

How a sampled plan becomes motion, `mode`:

- `tour` (default). The global graph proposes, the policy votes. The first-target options
  are `guide_tsp`'s (clusters of the global graph's boosted utilities, each scored by weight
  per metre of distance plus tour regret); each option's score is multiplied by
  1 + `prior_weight` x the share of the sampled plans heading for it (`target_votes`). The
  executed chunk is the first T_a steps of the sample that makes the most progress toward
  the chosen target, cut where it leaves a shortest known path to it, or that path itself
  when no sample heads there (`fallback_share`). Measured on 6 dev mazes (never the test
  mazes): 491 m against 610 m for mode `policy`, 508 m for `guide_tsp`, 544 m for
  `greedy_utility`; on 8 further dev mazes 455 m (prior_weight 0: 444 m, 3: 455 m) against
  `guide_tsp` 426 m and `greedy_utility` 450 m; on 100 fresh mazes `guide` is level with
  `guide_tsp` (-0.4 % +- 1.0, paired) and `greedy_utility` (-0.3 % +- 2.7) and 3.5 % +- 2.7
  shorter than `dare`. A stronger prior hurts (6 dev mazes:
  prior_weight 10 / 30 -> 511 / 538 m): the small CPU-trained policy (28 % first-step
  accuracy on held-out expert steps) is a weak guide, and with it `guide` is `guide_tsp`
  up to the order of ties, so its distances differ from `guide_tsp`'s by the chaos of
  exploration (one dev maze: 654 vs 500 m from tie-breaking alone), not by skill. The
  ground-truth expert's own planned path (its known-free prefix) as the only vote did not
  help either (6 dev mazes: 522 / 519 / 527 m at prior_weight 1 / 3 / 10), and forcing the
  option nearest the expert's next viewpoint made the robot oscillate (over 3,000 m): a
  prior can only re-weight the tour's options, so in this mode the policy's ceiling is close
  to `guide_tsp`'s. One DAgger round (24 policy-mode rollouts on the training mazes, every state
  relabelled by the replanning expert, 6,104 states added to the 3,716 expert steps) gave
  16 % held-out first-step accuracy, 669 m in mode policy (610 m before) and 490 m in mode
  tour (491 m): no gain at this scale.
- `policy`: the plans themselves are driven. Sample and rank: the plan whose feasible path
  reaches the most new frontier utility per metre wins (`rank_candidates`); `candidates=1`
  is the plain receding-horizon policy of the paper. Each predicted step becomes a
  feasible move: the lattice neighbour it names when that edge is known free, else the
  known-free neighbour whose direction best matches the policy's soft (expected)
  direction. A step that stays put, or a plan that has revealed nothing for `stall_steps`
  moves, hands over to one step along the shortest path to the nearest useful node
  (Yamauchi's rule) until new cells appear. With the small policy a single sample wanders
  (1078 m mean on the default test mazes against 604 m with 8).

The robot moves only along known-free lattice edges in both modes.

`lookahead=K` (mode tour; 0 = off, the default): the chosen target is checked by simulation.
Candidates are guide's own choice and gated greedy's K best targets (`lookahead_targets=greedy`)
or guide's K best-scored tour options (`tour`); each is rolled out by gated greedy on
`lookahead_samples` maps drawn from the block model (`BlockLookahead`, as `sampled_lookahead`),
and the plans are driven toward the one whose rollouts are shortest. With K = 3 on the default
test mazes: 441.0 m (greedy candidates) and 489.7 m (tour options) against 484.0 m without; on
100 fresh mazes -4.1 % +- 3.0 against `guide` without it, level with `sampled_lookahead`, at
about 0.3-0.5 s a decision instead of 35 ms (docs/findings.md). The rollouts continue with gated
greedy, so they price greedy's candidates better than guide's tour options. With
`lookahead_commit` (on unless set false) the robot keeps the lookahead's target, without new
rollouts, until it is reached or no longer a target, as the rollouts themselves assumed: the
test mazes 435.7 m, and +0.9 % +- 2.0 on 100 fresh mazes against re-deciding at every sampled
decision, at a third of the time per planner call. A full decision takes about 150 ms median in one
process (2026-11-25, after the faster rollouts of that day; 270 ms before).
`lookahead_workers=2` forks a second process that takes rollouts from the same queue, and gated
greedy's candidates start rolling out before guide's own prediction and denoising: the same routes,
and about 87-95 ms median a full decision on 2 cores (`pipeline.planners.extensions.rollout_worker`). It is off by
default because `guide benchmark --workers 2` already keeps both cores busy with episodes.
`lookahead_rollout=fast` rolls out plain greedy (no sliver gate) that walks each target's whole
path before choosing again: half the time a full decision (127 against 248 ms median, one spell), but on 50
fresh mazes +5.2 % +- 4.2 longer than with the default `full` rollouts (gated greedy choosing at
every node): it gives up most of the lookahead's gain, so it stays an option (docs/findings.md).

Checkpoints: `checkpoint` wins; else models/planner_guide/policy.pt (models/planner_dare/ for
`dare`) from the pipeline; else the default shipped in pipeline/assets/ when present.
"""

from __future__ import annotations

import warnings
from dataclasses import replace

import numpy as np

from pipeline.prediction.global_graph import KNOWN
from pipeline.prediction.graph_observation import GraphObservation, observe
from pipeline.world.maps import GroundTruthMap
from pipeline.prediction.node_predictor import DEFAULT_COUNT_THRESHOLD, DEFAULT_THRESHOLD
from pipeline.planners.options import check_int, check_number
from pipeline.planners.registry import register_planner
from pipeline.world.planner import Waypoint
from pipeline.planners.guide.guide_tsp import GuideTspPlanner
from pipeline.prediction.node_predictor import InpaintFn
from pipeline.models.defaults import block_model_for, cached_policy, resolve_policy_path
from pipeline.planners.extensions.sampled_lookahead import BlockLookahead, gated_greedy_like
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE
from pipeline.world.planner import Observation

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
            stacklevel=3,
        )


class _DiffusionPlanner(GuideTspPlanner):
    """Shared receding-horizon loop of the diffusion planners (modes `tour` and `policy`)."""

    kind = "guide"  # which trained policy (guide or dare)
    needs_policy = True
    predicts = True
    region_evaluation = True

    def __init__(
        self,
        checkpoint: str | None = None,
        num_inference_steps: int | None = None,
        sampler: str | None = None,
        action_steps: int | None = None,
        inpainter_checkpoint: str | None = None,
        inpaint: InpaintFn | None = None,
        policy=None,
        mode: str = "tour",
        prior_weight: float = 1.0,
        min_utility: int = 2,
        threshold: float = DEFAULT_THRESHOLD,
        min_component: int = 3,
        count_threshold: float | None = DEFAULT_COUNT_THRESHOLD,
        stall_steps: int = 3,  # mode policy; dev mazes (6 x 100 m): 3 -> 634 m, 6 -> 673 m (candidates=8)
        candidates: int = 8,  # plans sampled per decision; mode policy with 1 = the plain policy of the paper
        lookahead: int = 0,  # mode tour: roll out the best `lookahead` options on block-model maps; 0 = off
        lookahead_samples: int = 4,
        lookahead_targets: str = "greedy",  # what is rolled out: guide's choice + gated greedy's best, or guide's best tour options
        lookahead_commit: bool | None = None,  # keep the lookahead's target until reached or no longer a target; None = on
        lookahead_rollout: str | None = None,  # full (gated greedy, a choice per node) or fast (greedy walking whole paths); None = full
        lookahead_workers: int | None = None,  # 2: the rollouts shared with a forked second process; None = 1
        block_model: str | None = None,
        **tour_options,
    ):
        # Options that need no model are checked before anything is loaded.
        if mode not in ("tour", "policy"):
            raise ValueError(f"mode must be tour or policy, got {mode!r}")
        check_int("lookahead", lookahead, 0, note="0 = off; the number of best tour options rolled out")
        if lookahead == 1 or (lookahead and mode != "tour"):
            raise ValueError(f"lookahead must be 0 (off) or at least 2, in mode tour; got {lookahead!r} in mode {mode}")
        BlockLookahead.check_options(lookahead_samples, 20.0, 0.0, 1.0, 1 if lookahead_workers is None else lookahead_workers)
        if lookahead_targets not in ("greedy", "tour"):
            raise ValueError(f"lookahead_targets must be greedy or tour, got {lookahead_targets!r}")
        if lookahead_rollout not in (None, "fast", "full"):
            raise ValueError(f"lookahead_rollout must be fast or full, got {lookahead_rollout!r}")
        lookahead_only = (block_model, lookahead_commit, lookahead_rollout, lookahead_workers)
        if any(option is not None for option in lookahead_only) and not lookahead:
            raise ValueError("block_model, lookahead_commit, lookahead_rollout or lookahead_workers is given but the "
                             "lookahead is off; add lookahead=3")
        check_number("prior_weight", prior_weight, 0.0, note="0 = the policy does not vote")
        check_int("stall_steps", stall_steps, 1)
        check_int("candidates", candidates, 1)
        if sampler is not None and sampler not in ("ddpm", "ddim"):
            raise ValueError(f"sampler must be ddpm or ddim, got {sampler!r}")
        if self.predicts:
            super().__init__(min_utility, inpainter_checkpoint, inpaint, threshold=threshold, min_component=min_component,
                             count_threshold=count_threshold, **tour_options)
        else:
            super().__init__(
                min_utility, None, lambda image: np.zeros(np.shape(image), np.float32),
                threshold=threshold, min_component=min_component, count_threshold=count_threshold, **tour_options,
            )
            self.predictor = None
            self.predictor_source = "no prediction (observed graph only)"
        if policy is None:
            path = resolve_policy_path(self.kind, checkpoint)
            policy, trained_on = cached_policy(path)
            variant = trained_on.get("variant")
            if variant is not None and variant != self.kind:
                raise ValueError(
                    f"{path}: a {variant} policy (trained on {variant} observations); "
                    f"{self.name} needs a {self.kind} policy"
                )
            if self.predicts:
                warn_if_trained_at_other_taus(path, trained_on, threshold, count_threshold)
            self.trained_models.append((str(path), trained_on.get("protocol")))
            self.policy_source = str(path)
        else:
            self.policy_source = "injected policy"
        self.policy = policy
        config = policy.config
        # Bounded by the loaded policy: K denoising steps pick K of its T training timesteps
        # (diffusers fails deep in sampling otherwise), T_a executed steps come from its T_p.
        steps = config.num_inference_steps if num_inference_steps is None else num_inference_steps
        check_int("num_inference_steps", steps, 1, config.num_train_timesteps, note="the policy's num_train_timesteps")
        self.num_inference_steps = int(steps)
        if sampler is not None and sampler != config.sampler:
            policy = self._with_sampler(policy, sampler)
            self.policy = policy
        steps = config.action_steps if action_steps is None else action_steps
        check_int("action_steps", steps, 1, config.horizon, note="the policy's horizon")
        self.action_steps = int(steps)
        self.stall_steps = int(stall_steps)
        self.candidates = int(candidates)
        self.mode = mode
        self.prior_weight = float(prior_weight)
        self.lookahead: BlockLookahead | None = None
        self.lookahead_k, self.lookahead_targets = int(lookahead), lookahead_targets
        self.lookahead_commit = lookahead_commit is not False
        self.lookahead_rollout = lookahead_rollout or "full"
        lookahead_source = ""
        if lookahead:
            model, lookahead_source = block_model_for(block_model)
            self.lookahead = BlockLookahead(model, lookahead_samples, per_target=self.lookahead_rollout == "fast",
                                            workers=lookahead_workers or 1)
            processes = f" in {self.lookahead.workers} processes" if self.lookahead.workers > 1 else ""
            lookahead_source = (f"; lookahead {lookahead} x {lookahead_samples} maps, {self.lookahead_rollout} rollouts"
                                f"{processes}, {lookahead_source}")
        # The policy was trained on graphs of its own max_nodes, and the variant fixes region evaluation;
        # every other field of a `global_graph=` option is kept.
        self.global_config = replace(self.global_config, max_nodes=config.max_nodes,
                                     use_region_evaluation=self.region_evaluation)
        self.description = (
            f"{self.base_description} [mode {mode}; policy {self.policy_source}; {self.predictor_source}; "
            f"{self.gate_source}; K={self.num_inference_steps}{lookahead_source}]"
        )

    @staticmethod
    def _with_sampler(policy, sampler: str):
        """A shallow copy of `policy` (weights shared) that samples with another diffusers scheduler."""
        import copy

        from diffusers import DDIMScheduler, DDPMScheduler

        variant = copy.copy(policy)
        variant.config = replace(policy.config, sampler=sampler)
        scheduler_class = DDIMScheduler if sampler == "ddim" else DDPMScheduler
        variant.inference_scheduler = scheduler_class.from_config(policy.noise_scheduler.config)
        return variant

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        super().reset(ground_truth, protocol, seed)
        import torch

        self.history: list[GraphObservation] = []
        self.encodings: list = []
        self.queue: list[np.ndarray] = []
        self.moves_without_news = 0
        self.decisions = 0
        self.fallbacks = 0
        self.generator = torch.Generator().manual_seed(int(seed))
        if self.lookahead is not None:
            self.lookahead.reset(ground_truth)
            self.lookahead_rng = np.random.default_rng(seed)  # its own draws: the rest of the planner's are unchanged
        self.lookahead_choice: int | None = None

    # ------------------------------------------------------------------ decisions
    def observe_step(self, observation: Observation) -> GraphObservation:
        predicted, counted = self.predict_with_counted() if self.predicts else (None, None)
        self.global_graph.update(observation.belief, observation.position, predicted, self.visited, counted)
        obs = observe(self.global_graph, observation.position, self.policy.config.max_neighbors)
        self.history.append(obs)
        self.encodings.append(None)
        del self.history[: -self.policy.config.obs_steps]
        del self.encodings[: -self.policy.config.obs_steps]
        return obs

    def encode(self, index: int):
        """z of history entry `index`, encoded once and kept (a graph is encoded for at most T_o decisions)."""
        import torch

        if self.encodings[index] is None:
            o = self.history[index]
            with torch.inference_mode():
                self.encodings[index] = self.policy.encoder(
                    torch.from_numpy(o.features)[None], torch.from_numpy(o.node_mask)[None],
                    torch.from_numpy(o.neighbors.astype(np.int64))[None], torch.tensor([o.robot]),
                )
        return self.encodings[index]

    def sample_plans(self) -> tuple[np.ndarray, np.ndarray]:
        """(C, T_p, 2) lattice steps and (C, T_p, 2) soft directions: `candidates` samples, one batched pass."""
        import torch

        steps = self.policy.config.obs_steps
        picked = [max(0, len(self.history) - steps + k) for k in range(steps)]  # the first observation repeats
        obs_z = torch.stack([self.encode(i)[0] for i in picked])[None].expand(self.candidates, -1, -1)
        with torch.inference_mode():
            out = self.policy.predict_action(None, num_inference_steps=self.num_inference_steps, generator=self.generator, obs_z=obs_z)
        return out["deltas"].numpy(), out["expected"].numpy()

    def sample_steps(self) -> tuple[np.ndarray, np.ndarray]:
        """(T_p, 2) lattice steps and (T_p, 2) soft directions for the current history (mode policy)."""
        deltas, expected = self.sample_plans()
        best = self.rank_candidates(deltas, expected) if self.candidates > 1 else 0
        return deltas[best], expected[best]

    def candidate_paths(self, robot: int, deltas: np.ndarray, expected: np.ndarray) -> list[list[int]]:
        """Each sampled plan driven on the known graph: its lattice nodes from `robot` (feasible moves only)."""
        paths = []
        for c in range(len(deltas)):
            path = [robot]
            for k in range(len(deltas[c])):
                nxt = self.feasible_move(path[-1], deltas[c, k], expected[c, k])
                if nxt is None:
                    break
                path.append(nxt)
            paths.append(path)
        return paths

    def rank_candidates(self, deltas: np.ndarray, expected: np.ndarray) -> int:
        """Index of the sampled plan that sees the most new frontier per metre when driven on the known graph.

        Mode policy. Each candidate's T_p steps are mapped to feasible moves as they would be executed;
        its score is the global graph's utility u(v) (frontier utility boosted by the predicted
        nodes in range; plain frontier utility for `dare`) of the distinct unvisited nodes it reaches, with
        each later step weighted less (0.8 per step), over its length. Plans that reach no
        frontier are ordered by how close they end to the nearest useful node (shortest path
        on the known graph), so that in explored space the policy's proposal that heads
        toward unexplored space wins. Ties keep the first sample.
        """
        from scipy.sparse.csgraph import dijkstra

        graph = self.graph
        assert graph is not None
        robot = int(np.argmin(np.hypot(*(graph.node_world - self.history[-1].positions[0]).T)))
        useful = self.useful_nodes()
        to_useful = (
            dijkstra(graph.adjacency(), directed=False, indices=useful, min_only=True)
            if useful.size else np.zeros(graph.node_count)
        )
        # u(v) of the global graph (Sec. IV-B.3): frontier utility boosted by predicted nodes in range.
        utility = np.zeros(graph.node_count)
        gg = self.global_graph
        known = gg.types == KNOWN
        utility[gg.lattice_ids[known]] = gg.utility[known]
        scores = np.zeros(len(deltas))
        scale = graph.spec.node_resolution / 4.0  # lengths in metres of the 4 m benchmark lattice, at any scale
        for c, path in enumerate(self.candidate_paths(robot, deltas, expected)):
            seen, gain, length = set(), 0.0, 0.0
            for k, (node, nxt) in enumerate(zip(path[:-1], path[1:])):
                length += float(np.hypot(*(graph.node_world[nxt] - graph.node_world[node])))
                if nxt not in seen and not self.visited[nxt]:
                    gain += (0.8**k) * float(utility[nxt])
                seen.add(nxt)
            end = path[-1]
            remaining = float(to_useful[end]) if np.isfinite(to_useful[end]) else 1e6
            scores[c] = gain / (length / scale + 1.0) - 1e-6 * remaining / scale
        return int(np.argmax(scores))

    def target_votes(self, robot: int, paths: list[list[int]], options: dict) -> np.ndarray:
        """How much the sampled plans head for each first-target option, in [0, 1] (mode tour).

        A plan's progress toward a target is how much shorter its global-graph distance is at
        the plan's last node than at the robot, per metre driven (1 = straight at it). The
        vote of an option is the plans' mean progress toward it.
        """
        graph = self.graph
        assert graph is not None
        gg = self.global_graph
        known_ids = gg.lattice_ids[gg.types == KNOWN]
        distance = options["target_distance"][options["firsts"]]  # (options, global-graph rows)
        start = distance[:, np.searchsorted(known_ids, robot)]
        votes = np.zeros(len(options["firsts"]))
        for path in paths:
            if len(path) < 2:
                continue
            length = float(np.hypot(*np.diff(graph.node_world[path], axis=0).T).sum())
            end = distance[:, np.searchsorted(known_ids, path[-1])]
            with np.errstate(invalid="ignore"):  # an unreachable option (inf - inf) gets no vote
                progress = np.where(np.isfinite(start) & np.isfinite(end), start - end, 0.0)
            votes += np.clip(progress / length, 0.0, 1.0)
        return votes / max(len(paths), 1)

    def feasible_move(self, node: int, step: np.ndarray, direction: np.ndarray) -> int | None:
        """The lattice node reached by `step` from `node` if that edge is known free, else the best-matching neighbour."""
        graph = self.graph
        assert graph is not None
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

    def plan(self, observation: Observation) -> list[Waypoint]:
        _, robot, dist, pred, useful = self.locate(observation)
        if useful.size == 0:
            return []  # nothing reachable is left to explore
        if self.mode == "tour":
            return self.plan_tour(observation, robot, dist, pred, useful)
        return self.plan_policy(observation, robot)

    def plan_tour(self, observation: Observation, robot: int, dist: np.ndarray, pred: np.ndarray, useful: np.ndarray) -> list[Waypoint]:
        """Mode tour: the policy's samples vote on the frontier-tour first target; T_a steps of the best-aligned sample run.

        The first-target options and their scores are `guide_tsp`'s (clusters of the global
        graph's boosted utilities, weight per metre of distance + tour regret). Each option's
        score is multiplied by 1 + `prior_weight` x its vote (`target_votes`): the learned
        prior says which way the expert would go, the global graph says what is worth going
        for. The executed chunk is the first T_a steps of the sample that makes the most
        progress toward the chosen target, cut where it leaves a shortest known path to it;
        when no sample heads there, the shortest known path itself.
        """
        graph = self.graph
        assert graph is not None
        target = self.previous
        queued = None  # the next step of the last chunk, when it is still on the way to a target
        if self.queue and target is not None and target in set(useful.tolist()):
            nxt = int(self.queue[0])
            if nxt in set(graph.neighbours(robot).tolist()) and dist[nxt] < np.inf:
                queued = nxt
        kept = self.lookahead_choice
        committed = self.lookahead_commit and kept is not None and kept != robot and kept in set(useful.tolist())
        rollouts, greedy = None, []
        if queued is None and self.lookahead is not None and not committed and self.lookahead_targets == "greedy":
            ranked = useful[np.argsort(-graph.utility[useful] / dist[useful], kind="stable")]
            greedy = [int(t) for t in ranked[: self.lookahead_k]]
            if len(greedy) > 1:  # there will be rollouts: gated greedy's best start now, beside the prediction and denoising
                rollouts = self.lookahead.start(self._rollout_planner(), observation, greedy, pred, self.lookahead_rng)
        self.observe_step(observation)
        self.decisions += 1
        if queued is not None:
            self.queue.pop(0)
            self.last_decision = {"target": target, "sampled": False, "fallback": False, "fallback_share": self.fallbacks / self.decisions}
            return [tuple(map(float, graph.node_world[queued]))]
        self.queue = []
        options = self.first_target_scores(robot, dist, useful)
        deltas, expected = self.sample_plans()
        paths = self.candidate_paths(robot, deltas, expected)
        votes = self.target_votes(robot, paths, options)
        scores = options["scores"] * (1.0 + self.prior_weight * votes)
        best = int(np.argmax(scores))
        tour = options["tours"][best]
        target = tour[0]
        costs = None
        if committed:
            target = kept  # committed: the rollouts assumed the robot heads there until reached or no longer a target
            tour = [target] + [t for t in tour if t != target]
        elif self.lookahead is not None:
            # Candidate targets, each rolled out on maps drawn from the block model; the shortest wins.
            if self.lookahead_targets == "tour":
                candidates = [options["tours"][j][0] for j in np.argsort(-scores, kind="stable")[: self.lookahead_k]]
            else:  # guide's own choice, then gated greedy's best by utility per metre
                candidates = list(dict.fromkeys([target] + greedy))
            if len(candidates) > 1:
                if rollouts is None:
                    rollouts = self.lookahead.start(self._rollout_planner(), observation, candidates, pred, self.lookahead_rng)
                costs = self.lookahead.finish(rollouts, candidates)
                target = candidates[int(np.argmin(costs))]
                tour = [target] + [t for t in tour if t != target]
            self.lookahead_choice = target
        self.previous = target
        # The chunk: a sample's steps while each one shortens the known-graph distance to the target by its length.
        to_target, _ = graph.shortest_paths(target)
        chunk: list[int] = []
        for path in sorted(paths, key=lambda q: to_target[q[min(len(q) - 1, self.action_steps)]]):
            run = []
            for node, nxt in zip(path[: self.action_steps], path[1 : self.action_steps + 1]):
                step = float(np.hypot(*(graph.node_world[nxt] - graph.node_world[node])))
                if not to_target[nxt] < to_target[node] - step + 1e-6:
                    break
                run.append(nxt)
            if run:
                chunk = run
                break
        aligned = bool(chunk)
        if not chunk:
            self.fallbacks += 1
            chunk = graph.path_from_predecessors(pred, target)[1 : 1 + self.action_steps]
        self.queue = chunk[1:]
        self.last_decision = {
            "target": target,
            "tour": tour,
            "votes": votes,
            "lookahead_costs": costs,
            "sampled": True,
            "fallback": not aligned,
            "fallback_share": self.fallbacks / self.decisions,
        }
        return [tuple(map(float, graph.node_world[chunk[0]]))]

    def _rollout_planner(self):
        """What the lookahead rolls out: gated greedy in this planner's graph state (ungated for fast rollouts)."""
        return gated_greedy_like(self, gated=self.lookahead_rollout == "full")

    def plan_policy(self, observation: Observation, robot: int) -> list[Waypoint]:
        """Mode policy: the sampled plans ranked by `rank_candidates`, stall guard as the safety net."""
        graph = self.graph
        assert graph is not None
        new_free = observation.changed is None or bool(np.any(observation.belief.reshape(-1)[observation.changed] == FREE))
        self.moves_without_news = 0 if new_free else self.moves_without_news + 1
        self.observe_step(observation)
        self.decisions += 1
        move = None
        sampled = False
        if self.moves_without_news < self.stall_steps:
            if not self.queue:
                sampled = True
                steps, directions = self.sample_steps()
                self.queue = [np.concatenate([s, d]) for s, d in zip(steps[: self.action_steps], directions[: self.action_steps])]
            planned = self.queue.pop(0)
            move = self.feasible_move(robot, planned[:2].astype(np.int64), planned[2:])
            exact = move is not None and np.array_equal(graph.node_ij[move] - graph.node_ij[robot], planned[:2].astype(np.int64))
            if not exact:
                self.queue = []  # the rest of the chunk assumed this step: re-plan next time
        if move is None:
            self.fallbacks += 1
            self.queue = []
            waypoints = self.nearest_useful_step(robot)
            self.last_decision = {"fallback": True, "sampled": sampled, "fallback_share": self.fallbacks / self.decisions}
            return waypoints
        self.last_decision = {"fallback": False, "sampled": sampled, "fallback_share": self.fallbacks / self.decisions}
        return [tuple(map(float, graph.node_world[move]))]


@register_planner("guide")
class GuidePlanner(_DiffusionPlanner):
    """GUIDE: the diffusion policy on the region-evaluated global graph."""

    base_description = "GUIDE: diffusion policy conditioned on the region-evaluated global graph (predicted nodes)"
    description = base_description


@register_planner("guide_noregion")
class GuideNoRegionPlanner(_DiffusionPlanner):
    """GUIDE without region evaluation: every predicted node enters the graph (paper Table III)."""

    base_description = "GUIDE w/o region evaluation: the guide policy on a graph with every predicted node"
    description = base_description
    region_evaluation = False


@register_planner("dare")
class DarePlanner(_DiffusionPlanner):
    """DARE: the same diffusion policy trained and run on the observed graph only."""

    base_description = "DARE: diffusion policy on the observed graph only (no prediction, no region evaluation)"
    description = base_description
    kind = "dare"
    predicts = False
    region_evaluation = False
    sliver_gate_default = False  # DARE as published; `dare:sliver_gate=true` adds our gate
