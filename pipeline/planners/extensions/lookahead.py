"""The block-model lookahead: candidate targets tried by simulation on maps drawn from what is seen.

At a decision the block model (`pipeline.models.modeling_block_model`) gives P(free) of every
block of the map from what has been seen; `samples` block maps are drawn from those
probabilities, each cut to `horizon_m` beyond the known free space (a model sees no further
with any use). On each drawn map, each candidate target is rolled out: a copy of the rollout
planner (gated greedy) heads for it until it is reached or stops being a target, then goes on
by its own rule until that map is explored. A candidate's cost is its mean rollout distance.
`sampled_lookahead` and `guide:lookahead=K` consult this simulator; with `workers=2` a forked
second process (`pipeline.planners.extensions.rollout_worker`) shares the rollouts.
"""

from __future__ import annotations

import copy
import warnings
from dataclasses import dataclass, field
from typing import Annotated

import numpy as np

from pipeline.common.config import any_of, config_dataclass, flag, maybe, positive, real, text, validate, whole
from pipeline.models.modeling_block_model import BlockModel
from pipeline.planners.baselines.frontier import GreedyUtilityPlanner
from pipeline.planners.config import PlannerConfig, option
from pipeline.planners.extensions.rollout_worker import JobContext, RolloutWorker
from pipeline.planners.graph_planner import GraphPlanner
from pipeline.prediction.block_maps import block_index, block_shares, drawn_world, exit_steps, imagined_free
from pipeline.world.maps import GroundTruthMap, MapFrame, map_frame
from pipeline.world.planner import Observation
from pipeline.world.simulator import Episode

LOOKAHEAD_TARGETS = ("greedy", "tour")
LOOKAHEAD_ROLLOUTS = ("full", "fast")
WORKERS_NOTE = "2: the rollouts shared with a second process"


@config_dataclass
class RolloutSettings:
    """How `BlockLookahead` draws its maps and shares its rollouts (its constructor's numbers, from
    Python as well as from a planner's options)."""

    samples: Annotated[int, whole(1)] = 4
    horizon_m: Annotated[float, real(0.0, note="metres")] = 20.0
    exit_weight: Annotated[float, real(0.0)] = 0.0
    temperature: Annotated[float, positive()] = 1.0
    workers: Annotated[int, whole(1, 2, note=WORKERS_NOTE)] = 1


@config_dataclass
class LookaheadConfig(PlannerConfig):
    """The block-model lookahead of a planner that chooses among targets (the tour vote)."""

    part = "the lookahead (ours, mode tour)"
    renamed = {"block_model": "block_model_file"}

    lookahead: Annotated[
        int,
        any_of(whole(0, 0), whole(2), description="0 (off) or a whole number >= 2 (the best tour options rolled out)"),
    ] = option(
        0,
        "mode tour: roll out this many candidate targets on maps drawn from the block model and head for the "
        "shortest (0 = off)",
    )
    lookahead_samples: Annotated[int, whole(1)] = option(4, "maps drawn per lookahead decision")
    lookahead_targets: Annotated[str, text(LOOKAHEAD_TARGETS)] = option(
        "greedy",
        "greedy: guide's choice and gated greedy's best targets are rolled out; tour: guide's best tour options",
    )
    lookahead_commit: Annotated[bool | None, maybe(flag(), "on")] = option(
        None, "keep the lookahead's target until reached or no longer a target, as the rollouts assumed [None: on]"
    )
    lookahead_rollout: Annotated[str | None, maybe(text(LOOKAHEAD_ROLLOUTS), "full")] = option(
        None,
        "full (gated greedy, a choice at every node) or fast (greedy walking each target's whole path) [None: full]",
    )
    lookahead_workers: Annotated[int | None, maybe(whole(1, 2, note=WORKERS_NOTE), "1")] = option(
        None, "2: the rollouts shared with a forked second process, the same routes [None: 1]"
    )
    block_model_file: Annotated[str | None, maybe(text())] = option(
        None, "the block model [default: models/block_model/block_model.pt, else the shipped one]"
    )

    def check(self) -> None:
        super().check()
        lookahead_only = (self.block_model_file, self.lookahead_commit, self.lookahead_rollout, self.lookahead_workers)
        if any(value is not None for value in lookahead_only) and not self.lookahead:
            raise ValueError(
                "block_model_file, lookahead_commit, lookahead_rollout or lookahead_workers is given but "
                "the lookahead is off; add lookahead=3"
            )

    def model_slots(self) -> dict[str, str]:
        return {**super().model_slots(), **({"block_model_file": "block_model"} if self.lookahead > 0 else {})}


#: What a gated-greedy rollout reads of a graph planner: its lattice graph, visits and gate state.
GRAPH_STATE = (
    "min_utility",
    "graph",
    "visited",
    "protocol",
    "rng",
    "gate",
    "gate_source",
    "_gated",
    "_gate_known",
    "_gate_big",
    "robot",
    "belief",
)


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

    def __init__(
        self,
        model: BlockModel,
        samples: int = 4,
        horizon_m: float = 20.0,
        exit_weight: float = 0.0,
        temperature: float = 1.0,
        per_target: bool = False,
        workers: int = 1,
    ):
        validate(
            RolloutSettings,
            {
                "samples": samples,
                "horizon_m": horizon_m,
                "exit_weight": exit_weight,
                "temperature": temperature,
                "workers": workers,
            },
        )
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

    def reset(self, frame: MapFrame) -> None:
        """The map's frame (size, start and cell size) is all the rollouts know of it."""
        self.close()  # a worker holds the last map's lattice
        frame = map_frame(frame)
        self.blocks, self.block_grid = block_index(frame.shape, frame.cell_size, self.model.config.block_m)
        self.start_cell, self.cell_size = frame.start_cell, frame.cell_size
        self.horizon_cells = int(round(self.horizon_m / frame.cell_size))

    def close(self) -> None:
        """Stop the worker process, if one runs."""
        if self._worker is not None:
            self._worker.close()
            self._worker = None

    def costs(
        self,
        planner: GreedyUtilityPlanner,
        observation: Observation,
        candidates: list[int],
        pred: np.ndarray,
        rng: np.random.Generator,
    ) -> np.ndarray:
        """Mean rollout distance (m) per candidate target; `pred`: the planner's known-graph predecessors from the robot."""
        return self.finish(self.start(planner, observation, candidates, pred, rng), candidates)

    def start(
        self,
        planner: GreedyUtilityPlanner,
        observation: Observation,
        candidates: list[int],
        pred: np.ndarray,
        rng: np.random.Generator,
    ) -> "Rollouts":
        """Draw the maps and, with a worker, start rolling out `candidates` there; `finish` collects.
        A planner with work of its own before it knows every candidate (`guide`'s denoising) starts
        the ones it knows first."""
        probability = self.model.free_probability(
            block_shares(observation.belief, self.blocks, self.block_grid), self.temperature
        )
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
        start = Episode.resume(
            world, context.planner.protocol, observation.belief, observation.cell, observation.position
        )
        exits = (
            exit_steps(free, imagined_free(observation.belief, self.blocks, drawn)) if self.exit_weight > 0 else None
        )
        return start, exits

    @staticmethod
    def rollout(
        trial: GreedyUtilityPlanner, episode: Episode, target: int, pred: np.ndarray, per_target: bool = False
    ) -> float:
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
