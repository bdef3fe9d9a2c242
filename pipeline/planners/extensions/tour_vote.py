"""The tour vote (ours, not the paper's): the global graph proposes, the diffusion policy votes.

`guide` in its default `mode=tour`. The first-target options come from `guide_tsp`'s tour
(`FrontierTour`) with guide's own defaults: each useful node of the global graph is an option,
scored by its boosted utility per metre of global-graph distance (`spread=0`, `beta=0`);
`spread=null,min_weight=30,beta=1.5,exact_max=9,max_moves=200` gives guide_tsp's clusters, each
scored by weight per metre of distance plus tour regret.
Each option's score is multiplied by 1 + `prior_weight` x how much the policy's sampled plans
head for it (`target_votes`): the learned prior says which way the expert would go, the global
graph says what is worth going for. The executed chunk is the first T_a steps of the sample
that makes the most progress toward the chosen target, cut where it leaves a shortest known
path to it, or that path itself when no sample heads there (`fallback_share`). Back at a node
with nothing new seen since it chose there, it keeps the target chosen there until reached or
news (`FrontierTour.keep_through_cycles`): the vote, drawn afresh at each decision, can
otherwise swing between two targets in turn and walk the robot back and forth until `max_steps`.

With `lookahead=K` the chosen target is checked by simulation (`BlockLookahead`): guide's own
choice and gated greedy's best targets (`lookahead_targets=greedy`), or guide's K best-scored
tour options (`tour`), are each rolled out by gated greedy on maps drawn from the block model,
and the plans are driven toward the one whose rollouts are shortest. With `lookahead_commit`
(on unless set false) that target is kept, without new rollouts, until it is reached or no
longer a target, as the rollouts assumed. Gated greedy's candidates start rolling out (in a
second process with `lookahead_workers=2`) before the prediction and the denoising.

The robot moves only along known-free lattice edges.
"""

from __future__ import annotations

from typing import Annotated, cast

import numpy as np

from pipeline.common.config import config_dataclass, real
from pipeline.models.defaults import block_model_for
from pipeline.planners.baselines.frontier import GreedyUtilityPlanner
from pipeline.planners.config import PlannerConfig, option
from pipeline.planners.extensions.lookahead import BlockLookahead, LookaheadConfig, gated_greedy_like
from pipeline.planners.guide.configuration_guide_tsp import TourOptions
from pipeline.planners.guide.guide import GuidePlanner, drive
from pipeline.planners.guide.guide_tsp import FrontierTour
from pipeline.planners.wrapper import PlannerWrapper
from pipeline.prediction.global_graph import KNOWN
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.protocol import Protocol


@config_dataclass
class TourVoteConfig(PlannerConfig):
    part = "the tour vote (ours, mode tour)"

    prior_weight: Annotated[float, real(0.0, note="0 = the policy does not vote")] = option(
        1.0,
        "mode tour: an option's score is multiplied by 1 + prior_weight x the share of samples heading for it "
        "(0: the policy does not vote)",
    )


class TourVote(PlannerWrapper):
    """guide_tsp's frontier tour (`FrontierTour`), its first target voted on by the samples of
    GUIDE's policy (`paper`, a `GuidePlanner`, which keeps the graphs and the T_o history)."""

    def __init__(
        self, paper: GuidePlanner, tour: TourOptions, vote: TourVoteConfig, lookahead: LookaheadConfig, description: str
    ):
        super().__init__(paper)
        self.paper = paper
        self.tour = FrontierTour(tour)
        self.prior_weight = float(vote.prior_weight)
        self.lookahead: BlockLookahead | None = None
        self.lookahead_k, self.lookahead_targets = int(lookahead.lookahead), lookahead.lookahead_targets
        self.lookahead_commit = lookahead.lookahead_commit is not False
        self.lookahead_rollout = lookahead.lookahead_rollout or "full"
        lookahead_source = ""
        if lookahead.lookahead:
            model, lookahead_source = block_model_for(lookahead.block_model_file)
            self.lookahead = BlockLookahead(
                model,
                lookahead.lookahead_samples,
                per_target=self.lookahead_rollout == "fast",
                workers=lookahead.lookahead_workers or 1,
            )
            processes = f" in {self.lookahead.workers} processes" if self.lookahead.workers > 1 else ""
            lookahead_source = (
                f"; lookahead {lookahead.lookahead} x {lookahead.lookahead_samples} maps, "
                f"{self.lookahead_rollout} rollouts{processes}, {lookahead_source}"
            )
        self.description = (
            f"{description} [mode tour; policy {paper.policy_source}; {paper.predictor_source}; "
            f"{paper.gate_source}; K={paper.num_inference_steps}{lookahead_source}]"
        )
        self.last_decision: dict = {}

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        self.paper.reset(frame, protocol, seed)
        self.tour.reset(protocol)
        self.queue: list[int] = []  # the rest of the executed chunk, while it still heads for the target
        self.decisions = 0
        self.fallbacks = 0
        if self.lookahead is not None:
            self.lookahead.reset(frame)
            self.lookahead_rng = np.random.default_rng(seed)  # its own draws: the rest of the planner's are unchanged
        self.lookahead_choice: int | None = None

    def plan(self, observation: Observation) -> list[Waypoint]:
        paper = self.paper
        graph, robot, dist, pred, useful = paper.locate(observation)
        if useful.size == 0:
            return []  # nothing reachable is left to explore
        target = self.tour.previous
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
            if (
                len(greedy) > 1
            ):  # there will be rollouts: gated greedy's best start now, beside the prediction and denoising
                rollouts = self.lookahead.start(self._rollout_planner(), observation, greedy, pred, self.lookahead_rng)
        paper.update_global_graph(observation)
        paper.observe(observation.position)
        self.decisions += 1
        if queued is not None:
            self.queue.pop(0)
            self.last_decision = {
                "target": target,
                "sampled": False,
                "fallback": False,
                "fallback_share": self.fallbacks / self.decisions,
            }
            return [cast(Waypoint, tuple(map(float, graph.node_world[queued])))]
        self.queue = []
        options = self.tour.first_target_scores(graph, paper.global_graph, robot, dist, useful)
        deltas, expected = paper.sample_plans()
        paths = drive(graph, robot, deltas, expected)
        votes = self.target_votes(robot, paths, options)
        scores = options["scores"] * (1.0 + self.prior_weight * votes)
        best = int(np.argmax(scores))
        tour = options["tours"][best]
        target = cast(int, tour[0])
        costs = None
        if committed:
            # committed: the rollouts assumed the robot heads there until reached or no longer a target
            target = cast(int, kept)
            tour = [target] + [t for t in tour if t != target]
        elif self.lookahead is not None:
            # Candidate targets, each rolled out on maps drawn from the block model; the shortest wins.
            if self.lookahead_targets == "tour":
                candidates = [options["tours"][j][0] for j in np.argsort(-scores, kind="stable")[: self.lookahead_k]]
            else:  # guide's own choice, then gated greedy's best by utility per metre
                candidates = list(dict.fromkeys([target] + greedy))
            if len(candidates) > 1:
                if rollouts is None:
                    rollouts = self.lookahead.start(
                        self._rollout_planner(), observation, candidates, pred, self.lookahead_rng
                    )
                costs = self.lookahead.finish(rollouts, candidates)
                target = cast(int, candidates[int(np.argmin(costs))])
                tour = [target] + [t for t in tour if t != target]
            self.lookahead_choice = target
        else:  # guide_tsp's cycle guard: back at a node with nothing new seen, the target chosen there is kept
            target = self.tour.keep_through_cycles(observation, robot, useful, target)
            tour = [target] + [t for t in tour if t != target]
        self.tour.previous = target
        # The chunk: a sample's steps while each one shortens the known-graph distance to the target by its length.
        to_target, _ = graph.shortest_paths(target)
        chunk: list[int] = []
        for path in sorted(paths, key=lambda q: to_target[q[min(len(q) - 1, paper.action_steps)]]):
            run = []
            for node, nxt in zip(path[: paper.action_steps], path[1 : paper.action_steps + 1]):
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
            chunk = graph.path_from_predecessors(pred, target)[1 : 1 + paper.action_steps]
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
        return [cast(Waypoint, tuple(map(float, graph.node_world[chunk[0]])))]

    def target_votes(self, robot: int, paths: list[list[int]], options: dict) -> np.ndarray:
        """How much the sampled plans head for each first-target option, in [0, 1].

        A plan's progress toward a target is how much shorter its global-graph distance is at
        the plan's last node than at the robot, per metre driven (1 = straight at it). The
        vote of an option is the plans' mean progress toward it.
        """
        graph = self.paper.graph
        assert graph is not None
        gg = self.paper.global_graph
        known_ids = gg.lattice_ids[gg.types == KNOWN]
        distance = options["option_distance"]  # (options, global-graph rows)
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

    def _rollout_planner(self) -> GreedyUtilityPlanner:
        """What the lookahead rolls out: gated greedy in this planner's graph state (ungated for fast rollouts)."""
        return gated_greedy_like(self.paper, gated=self.lookahead_rollout == "full")
