"""`sampled_lookahead`: gated greedy that looks one choice ahead on maps it imagines.

`oracle_lookahead` tries each of gated greedy's best targets in a copy of the episode on the
ground truth and is 16-18 % shorter than `greedy_utility`; this planner does the same without
the ground truth. At each decision the block model (`pipeline.models.modeling_block_model`)
gives P(free) of every 5 m maze block from what has been seen; `samples` block maps are drawn
from those probabilities, each cut to `horizon_m` beyond the known free space (a model sees
no further with any use: docs/findings.md). On each drawn map, each of the `k` best targets
(utility per metre) is tried: head for it until it is reached or stops being a target, then
gated greedy until that map is explored. The robot steps toward the target whose rollouts are
shortest on average and decides again. `k=1` is gated greedy itself.

With `switch_margin_m` set, the last decision's target stays among the candidates while it is
still a target, and the robot leaves it only for one whose mean rollout is shorter by more than
that margin: fresh maps are drawn at every decision, and without it the sampling noise alone can
turn the robot back and forth between two targets.

With `exit_weight` set, each rollout's cost also counts that weight times the way (through the
drawn map) from where the rollout ended to the nearest cell beside the horizon cut, where the
drawn free space goes on: the cut map is explored when a rollout ends, the real one is not, and
a rollout that ends far from what is left has a walk back the cut map does not charge.

With `workers=2` a second, forked process (`pipeline.planners.extensions.rollout_worker`) takes rollouts
from the same job counter as this one: the same costs and routes, in about 0.6 times the time on
a machine with two free cores.

With `temperature` T the maps are drawn from sigmoid(logit / T): the shipped model is
overconfident (its log-loss is lowest at T = 2), yet softer draws made routes no shorter, since
every target is rolled out on the same maps (docs/findings.md). Both options stay off.

Figures (docs/findings.md, "A lookahead on sampled maps"): about 0.14 s a decision at k 3,
4 samples, in one process (0.08 s with `workers=2`); with the block model fitted on 2560 mazes, 7.6-8.7 % shorter than `greedy_utility` on
100 fresh mazes. `BlockLookahead` is the simulator on its own, which `guide:lookahead=K` uses too.
"""

from __future__ import annotations

import copy
import warnings
from dataclasses import dataclass, field

import numpy as np

from pipeline.prediction.block_maps import block_index, block_shares, drawn_world, exit_steps, imagined_free
from pipeline.world.maps import GroundTruthMap
from pipeline.models.defaults import block_model_for
from pipeline.models.modeling_block_model import BlockModel
from pipeline.planners.graph_planner import GraphPlanner
from pipeline.planners.options import check_int, check_number
from pipeline.planners.registry import register_planner
from pipeline.world.planner import Waypoint
from pipeline.planners.baselines.frontier import GreedyUtilityPlanner
from pipeline.planners.extensions.rollout_worker import JobContext, RolloutWorker
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import Episode
from pipeline.world.planner import Observation

@register_planner("sampled_lookahead")
class SampledLookaheadPlanner(GreedyUtilityPlanner):
    """Gated greedy whose k best targets are each rolled out on block maps drawn from the block model."""

    sliver_gate_default = True
    description = ("gated greedy whose k best targets are each run to completion on maps drawn from the learned "
                   "block model; one step toward the one whose rollouts are shortest")

    def __init__(self, k: int = 3, samples: int = 4, horizon_m: float = 20.0, checkpoint: str | None = None,
                 switch_margin_m: float | None = None, exit_weight: float = 0.0, temperature: float = 1.0, min_utility: int = 2,
                 sliver_gate: bool | None = None, gate_file: str | None = None, model: BlockModel | None = None,
                 workers: int = 1):
        check_int("k", k, 1)
        if switch_margin_m is not None:
            check_number("switch_margin_m", switch_margin_m, 0.0)
            switch_margin_m = float(switch_margin_m)
        BlockLookahead.check_options(samples, horizon_m, exit_weight, temperature, workers)  # before anything is loaded
        super().__init__(min_utility, sliver_gate, gate_file)
        self.k, self.switch_margin_m = int(k), switch_margin_m
        model, self.model_source = block_model_for(checkpoint, model)
        self.model = model
        self.lookahead = BlockLookahead(model, samples, horizon_m, exit_weight, temperature, workers=workers)
        self.description = f"{type(self).description} [{self.model_source}; {self.gate_source}]"

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        super().reset(ground_truth, protocol, seed)
        self.lookahead.reset(ground_truth)
        self.last_target: int | None = None

    def plan(self, observation: Observation) -> list[Waypoint]:
        pred, ranked = self.ranked_targets(observation)
        if ranked.size == 0:
            return []
        choice = int(ranked[0])
        if self.k > 1 and ranked.size > 1:
            candidates = [int(t) for t in ranked[: self.k]]
            incumbent = 0  # the candidate a challenger must beat by the margin
            if self.switch_margin_m is not None and self.last_target is not None and self.last_target in set(ranked.tolist()):
                if self.last_target not in candidates:
                    candidates.append(self.last_target)
                incumbent = candidates.index(self.last_target)
            cost = self.lookahead.costs(self, observation, candidates, pred, self.rng)
            best = int(np.argmin(cost))
            if self.switch_margin_m is not None and cost[best] >= cost[incumbent] - self.switch_margin_m:
                best = incumbent
            choice = candidates[best]
        self.last_target = choice
        return self.waypoints_along(self.graph.path_from_predecessors(pred, choice))


#: What a gated-greedy rollout reads of a graph planner: its lattice graph, visits and gate state.
GRAPH_STATE = ("min_utility", "graph", "visited", "protocol", "rng", "gate", "gate_source", "_gated",
               "_gate_known", "_gate_big", "robot", "belief")


def gated_greedy_like(planner: GraphPlanner, gated: bool = True) -> GreedyUtilityPlanner:
    """A greedy planner in `planner`'s current graph state (shared, not copied; gated when `planner` is
    and `gated`): the rollout policy when a planner with another rule (`guide`) looks ahead. Rollouts
    run on copies."""
    view = GreedyUtilityPlanner.__new__(GreedyUtilityPlanner)
    view.__dict__.update({name: getattr(planner, name) for name in GRAPH_STATE})
    if not gated:
        view.gate, view._gated = None, None
    return view


class BlockLookahead:
    """The mean distance of gated-greedy rollouts toward each candidate target, on block maps drawn
    from the block model: the simulator `sampled_lookahead` and `guide:lookahead=K` consult.

    Each of `samples` maps is drawn from the model's P(free) per block given the current belief,
    cut to `horizon_m` beyond the known free space; on each, every candidate is tried on a copy of
    the rollout planner (head for it until reached or no longer a target, then that planner's rule
    until the drawn map is explored). Options as `sampled_lookahead`'s; with `per_target` the
    rollout planner walks each target's whole path before choosing again
    (`GreedyUtilityPlanner.finish_episode`).
    """

    def __init__(self, model: BlockModel, samples: int = 4, horizon_m: float = 20.0, exit_weight: float = 0.0,
                 temperature: float = 1.0, per_target: bool = False, workers: int = 1):
        self.check_options(samples, horizon_m, exit_weight, temperature, workers)
        self.model, self.samples, self.horizon_m = model, int(samples), float(horizon_m)
        self.exit_weight, self.temperature = float(exit_weight), float(temperature)
        self.per_target = bool(per_target)
        self.workers = int(workers) if RolloutWorker.available() else 1
        if self.workers != int(workers):
            warnings.warn("lookahead workers need os.fork (POSIX); the rollouts run in one process", stacklevel=2)
        self._worker: RolloutWorker | None = None

    def __getstate__(self) -> dict:
        """Copies and pickles leave the worker process behind (a copy forks its own when it needs one)."""
        return {**self.__dict__, "_worker": None}

    @staticmethod
    def check_options(samples: int, horizon_m: float, exit_weight: float, temperature: float, workers: int = 1) -> None:
        check_int("samples", samples, 1)
        check_number("horizon_m", horizon_m, 0.0)
        check_number("exit_weight", exit_weight, 0.0)
        check_number("temperature", temperature, 0.0, low_open=True)
        check_int("workers", workers, 1, 2, note="2: the rollouts shared with a second process")

    def reset(self, ground_truth: GroundTruthMap) -> None:
        """Only the map's size, start and cell size are read: the rollouts never see its cells."""
        self.close()  # a worker holds the last map's lattice
        self.blocks, self.block_grid = block_index(ground_truth.shape, ground_truth.cell_size, self.model.config.block_m)
        self.start_cell, self.cell_size = ground_truth.start_cell, ground_truth.cell_size
        self.horizon_cells = int(round(self.horizon_m / ground_truth.cell_size))

    def close(self) -> None:
        """Stop the worker process, if one runs."""
        if self._worker is not None:
            self._worker.close()
            self._worker = None

    def costs(self, planner: GreedyUtilityPlanner, observation: Observation, candidates: list[int], pred: np.ndarray,
              rng: np.random.Generator) -> np.ndarray:
        """Mean rollout distance (m) per candidate target; `pred`: the planner's known-graph predecessors from the robot."""
        return self.finish(self.start(planner, observation, candidates, pred, rng), candidates)

    def start(self, planner: GreedyUtilityPlanner, observation: Observation, candidates: list[int], pred: np.ndarray,
              rng: np.random.Generator) -> "Rollouts":
        """Draw the maps and, with a worker, start rolling out `candidates` there; `finish` collects.
        A planner with work of its own before it knows every candidate (`guide`'s denoising) starts
        the ones it knows first."""
        probability = self.model.free_probability(block_shares(observation.belief, self.blocks, self.block_grid),
                                                 self.temperature)
        drawn = [rng.random(probability.shape) < probability for _ in range(self.samples)]
        rollouts = Rollouts(JobContext(planner, observation, pred, drawn), list(dict.fromkeys(candidates)))
        if self.workers > 1 and rollouts.candidates:
            if self._worker is None:
                self._worker = RolloutWorker(self._run_job, planner, GRAPH_STATE)
            try:
                self._worker.start(rollouts.context, rollouts.candidates)
                rollouts.remote = True
            except (OSError, ValueError):  # the worker is gone (killed from outside): start another next time
                self.close()
        return rollouts

    def finish(self, rollouts: "Rollouts", candidates: list[int]) -> np.ndarray:
        """Mean rollout distance (m) of each of `candidates` (those started and any others), in their order."""
        self._run_batch(rollouts, rollouts.candidates, rollouts.remote)
        extra = [c for c in dict.fromkeys(candidates) if c not in set(rollouts.candidates)]
        if extra:
            remote = False
            if self._worker is not None and rollouts.remote:
                try:
                    self._worker.more(extra)
                    remote = True
                except (OSError, ValueError):
                    self.close()
            self._run_batch(rollouts, extra, remote)
        cost = np.zeros(len(candidates))
        for sample in range(self.samples):
            for i, target in enumerate(candidates):
                cost[i] += rollouts.costs[sample, target]
        return cost / self.samples

    def _run_batch(self, rollouts: "Rollouts", candidates: list[int], remote: bool) -> None:
        """Every drawn map's rollout of each of `candidates`: shared with the worker when `remote`."""
        count = self.samples * len(candidates)
        run = lambda job: self._run_job(rollouts.context, candidates, job)  # noqa: E731
        done: dict[int, float] = {}
        if remote and self._worker is not None:
            done = self._worker.take(count, run)
            try:
                done.update(self._worker.receive())
            except (EOFError, OSError):  # the worker died: its share runs here
                self.close()
        for job in range(count):
            cost = done[job] if job in done else run(job)
            rollouts.costs[job // len(candidates), candidates[job % len(candidates)]] = cost

    def _run_job(self, context: JobContext, candidates: list[int], job: int) -> float:
        """Job `job` of a batch: candidate `job % n` rolled out on drawn map `job // n` (n candidates)."""
        sample, target = divmod(job, len(candidates))
        target = candidates[target]
        if sample not in context.worlds:
            context.worlds[sample] = self._drawn_start(context, sample)
        start, exits = context.worlds[sample]
        planner = context.planner
        shared = {id(obj): obj for obj in (self, self.model, planner.gate)}  # read-only: not copied
        trial = copy.deepcopy(planner, shared)
        trial.graph.track_regions = False  # greedy never reads them
        trial.graph.lazy_utilities = not self.per_target  # counted when a rollout's ranking needs them
        episode = copy.deepcopy(start, {id(start.map): start.map, id(start.lidar): start.lidar})
        cost = self.rollout(trial, episode, target, context.pred, self.per_target)
        if exits is not None and np.isfinite(exits[episode.cell]):
            cost += self.exit_weight * float(exits[episode.cell]) * self.cell_size
        return cost

    def _drawn_start(self, context: JobContext, sample: int) -> tuple[Episode, np.ndarray | None]:
        """The episode that resumes the robot's on drawn map `sample`, and its exit distances (exit_weight)."""
        observation, drawn = context.observation, context.drawn[sample]
        free = drawn_world(observation.belief, self.blocks, drawn, self.horizon_cells)
        world = GroundTruthMap(free, self.start_cell, self.cell_size, name="sampled")
        start = Episode.resume(world, context.planner.protocol, observation.belief, observation.cell, observation.position)
        exits = (exit_steps(free, imagined_free(observation.belief, self.blocks, drawn))
                 if self.exit_weight > 0 else None)
        return start, exits

    @staticmethod
    def rollout(trial: GreedyUtilityPlanner, episode: Episode, target: int, pred: np.ndarray, per_target: bool = False) -> float:
        """On `trial` (a copy of the rollout planner): head for `target`, then its rule, on `episode`'s
        drawn map. The distance when that map is explored or no target is left (inf past the step
        limit): when the drawn map's walls hide the rest, its cost so far is the estimate."""
        distance = trial.finish_episode(episode, target, pred, per_target)
        return episode.distance if distance is None else distance


@dataclass
class Rollouts:
    """One decision's rollouts: their context, the candidates started, and the cost of each
    (map, candidate) pair run so far; `remote` when the worker has the context."""

    context: JobContext
    candidates: list[int]
    remote: bool = False
    costs: dict[tuple[int, int], float] = field(default_factory=dict)
