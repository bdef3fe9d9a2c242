"""Ground-truth coverage planners: `optimal` (docs/protocol.md's reference) and DARE's `expert`.

Both are oracles (`uses_ground_truth = True`) built on `pipeline.planners.references.coverage`:

- `optimal` plans one coverage tour on the ground truth at reset and hands the whole
  node-by-node path over at the first decision. Being the reference figure, it may cross
  ground-truth free cells not yet observed (`ignores_motion_rule = True`): the simulator
  checks its segments against the ground truth instead of the belief
  (`pipeline.planners.references.coverage.run_oracle_episode` does exactly that).
- `expert` reasons the same way (viewpoints on the ground-truth graph covering the
  ground-truth free cells the belief still lacks, ordered by an open TSP path) but moves
  only through known-free space, as every non-oracle planner must. It replans whenever
  the belief changed, warm-started from its previous tour, and takes the ground-truth
  shortest path to the next viewpoint as far as that path is known free.
"""

from __future__ import annotations

from dataclasses import replace
from typing import Annotated, cast

import numpy as np

from pipeline.common.config import config_dataclass, flag, maybe, positive, whole
from pipeline.planners.config import PlannerConfig, option
from pipeline.planners.graph_planner import GraphPlanner, LatticePlannerConfig
from pipeline.planners.references.coverage import (
    DEFAULT_LNS_ITERATIONS,
    DEFAULT_RESTARTS,
    CoveragePlan,
    coverage_plan,
    plan_coverage,
)
from pipeline.planners.references.coverage_model import CoverageModel, coverage_model
from pipeline.planners.registry import register_planner
from pipeline.world.geometry import segment_is_known_free
from pipeline.world.maps import GroundTruthMap
from pipeline.world.planner import Observation, OraclePlanner, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE

_RESTARTS_HELP = "randomised cover constructions of the first plan (the best wins)"
_LNS_HELP = "ruin-and-recreate rounds that polish the first plan (0 = none)"
_TIME_HELP = "seconds the first plan may take (None: no limit)"
_NO_LNS = "0 = no ruin-and-recreate rounds"


@config_dataclass
class OptimalConfig(PlannerConfig):
    description = "oracle: ground-truth coverage tour (viewpoints + open TSP), the protocol's reference"
    uses_ground_truth = True
    ignores_motion_rule = True
    lattice_planner = False

    # With no warm start, 0 restarts would construct no plan at all: the episode would end at once.
    restarts: Annotated[int, whole(1)] = option(DEFAULT_RESTARTS, _RESTARTS_HELP)
    lns_iterations: Annotated[int, whole(0, note=_NO_LNS)] = option(DEFAULT_LNS_ITERATIONS, _LNS_HELP)
    time_limit_s: Annotated[float | None, maybe(positive(), "no limit")] = option(60.0, _TIME_HELP)


@register_planner("optimal", OptimalConfig)
class OptimalPlanner(OraclePlanner):
    """The ground-truth coverage tour, executed in one go (oracle motion rule)."""

    description = OptimalConfig.description
    uses_ground_truth = True
    ignores_motion_rule = True

    def __init__(self, config: OptimalConfig = OptimalConfig()):
        restarts, lns_iterations, time_limit_s = config.restarts, config.lns_iterations, config.time_limit_s
        self.restarts = restarts
        self.lns_iterations = lns_iterations
        self.time_limit_s = time_limit_s
        self.tour: list[Waypoint] = []
        self._sent = False

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:  # type: ignore[override]  # an oracle: reset with the map itself
        self._episode = (ground_truth, protocol, seed)
        self.tour = []
        self._sent = False

    def plan(self, observation: Observation) -> list[Waypoint]:
        if self._sent:
            return []  # the tour is over and the episode is not complete: nothing left to cover
        # Planned at the first decision, not in reset, so its time is the decision time reported.
        ground_truth, protocol, seed = self._episode
        model, plan = coverage_plan(ground_truth, protocol, seed, self.restarts, self.lns_iterations, self.time_limit_s)
        self.model: CoverageModel = model
        self.coverage: CoveragePlan = plan
        self.tour = [cast(Waypoint, tuple(map(float, model.world[v]))) for v in plan.path]
        self._sent = True
        return list(self.tour[1:])


@config_dataclass
class ExpertConfig(LatticePlannerConfig):
    description = "oracle expert (DARE): ground-truth coverage TSP replanned on change, moves through known space"
    uses_ground_truth = True

    # The first plan has no warm start, so it needs a fresh construction; replans refine the
    # previous tour, so 0 fresh ones (and 0 LNS rounds, the default) make sense there.
    restarts: Annotated[int, whole(1)] = option(DEFAULT_RESTARTS, _RESTARTS_HELP)
    lns_iterations: Annotated[int, whole(0, note=_NO_LNS)] = option(DEFAULT_LNS_ITERATIONS, _LNS_HELP)
    replan_restarts: Annotated[int, whole(0, note="0 = only refine the previous tour")] = option(
        2, "fresh constructions that compete with the refined previous tour at a replan (0 = only refine it)"
    )
    replan_lns_iterations: Annotated[int, whole(0, note=_NO_LNS)] = option(
        0, "ruin-and-recreate rounds at a replan (0 = none)"
    )
    time_limit_s: Annotated[float | None, maybe(positive(), "no limit")] = option(60.0, _TIME_HELP)
    replan_time_limit_s: Annotated[float | None, maybe(positive(), "no limit")] = option(
        5.0, "seconds a replan may take (None: no limit)"
    )
    replan_on_change: Annotated[bool, flag()] = option(
        True, "replan whenever the belief changed (false: only the first plan)"
    )


@register_planner("expert", ExpertConfig)
class ExpertPlanner(GraphPlanner):
    """DARE's expert: ground-truth coverage tour, replanned on every change, known-free moves.

    Planning is `optimal`'s, over the ground-truth free cells the belief still lacks and
    from the robot's node. The first decision runs the full search (`restarts`,
    `lns_iterations`; with the same seed it is exactly `optimal`'s plan). Every later
    decision that comes with new cells replans: the previous tour, refined from the robot's
    node (pruned with what the path now sees, viewpoints moved, re-ordered), competes with
    `replan_restarts` fresh constructions (and `replan_lns_iterations` rounds) when a
    viewpoint has just been reached or a detour has just ended, and alone otherwise; only
    a shorter plan replaces it, so the planned remainder never grows while on plan.

    Motion obeys the normal rule. The robot takes the next edge of the ground-truth
    shortest path to the next viewpoint when that edge is known free (shortest paths are
    unique, so replanning halfway keeps to the same path). When it is not, the robot
    commits to a known-free detour (`_detour`) and follows it without replanning. One
    waypoint per decision.
    """

    description = ExpertConfig.description
    uses_ground_truth = True

    def __init__(self, config: ExpertConfig = ExpertConfig()):
        super().__init__(config)
        restarts, lns_iterations = config.restarts, config.lns_iterations
        replan_restarts, replan_lns_iterations = config.replan_restarts, config.replan_lns_iterations
        time_limit_s, replan_time_limit_s = config.time_limit_s, config.replan_time_limit_s
        replan_on_change = config.replan_on_change
        self.restarts = restarts
        self.lns_iterations = lns_iterations
        self.replan_restarts = replan_restarts
        self.replan_lns_iterations = replan_lns_iterations
        self.time_limit_s = time_limit_s
        self.replan_time_limit_s = replan_time_limit_s
        self.replan_on_change = replan_on_change

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:  # type: ignore[override]  # an oracle: reset with the map itself
        # DARE's lattice at every scale: the coverage model plans lattice paths and detours follow
        # the observed graph, whose door nodes (the building scale's) the model has no node for;
        # an edge valid only through a door node, walked straight, would break the motion rule.
        protocol = replace(protocol, door_graph=False) if protocol.uses_door_graph else protocol
        super().reset(ground_truth.frame, protocol, seed)
        self.model = coverage_model(ground_truth, protocol)
        self.seed = seed
        self.tour: list[int] = []  # local viewpoints still to visit, next first
        self.detour: list[int] = []  # committed known-free route (local nodes), next first
        self.planned = False
        self.fresh_search = True  # next replan also runs fresh constructions
        self.detours = 0  # times the ground-truth path's next edge was not known free

    def plan(self, observation: Observation) -> list[Waypoint]:
        graph = self.update_graph(observation)
        model = self.model
        robot = int(model.local[graph.nearest_node(observation.position)])
        if robot < 0:
            return []
        if self.tour and self.tour[0] == robot:
            self.tour.pop(0)
            self.fresh_search = True
        if self.detour:
            return self._step(self.detour.pop(0))
        known_free = observation.belief == FREE
        changed = observation.changed is None or observation.changed.size > 0
        if not self.planned or not self.tour or self.fresh_search or (changed and self.replan_on_change):
            self._replan(robot, known_free)
        if not self.tour:
            return []
        target = self.tour[0]
        path = model.path(robot, target)
        cells = model.node_cells
        if segment_is_known_free(known_free, tuple(cells[path[0]]), tuple(cells[path[1]])):
            return self._step(path[1])
        self.detour = self._detour(robot)
        self.detours += 1
        self.fresh_search = True
        if not self.detour:
            return []
        return self._step(self.detour.pop(0))

    # ------------------------------------------------------------------ internals
    def _step(self, node: int) -> list[Waypoint]:
        return [cast(Waypoint, tuple(map(float, self.model.world[node])))]

    def _replan(self, robot: int, known_free: np.ndarray) -> None:
        """Tour over the cells the belief lacks; the previous tour competes (warm start)."""
        model = self.model
        uncovered = model.uncovered(known_free)
        if not self.planned:
            # The first plan is exactly `optimal`'s (same search, same seed).
            self.rng = np.random.default_rng(self.seed)
            plan = plan_coverage(
                model,
                robot,
                uncovered,
                self.rng,
                self.restarts,
                lns_iterations=self.lns_iterations,
                time_limit=self.time_limit_s,
            )
        else:
            plan = plan_coverage(
                model,
                robot,
                uncovered,
                self.rng,
                self.replan_restarts if self.fresh_search else 0,
                warm_order=self.tour,
                lns_iterations=self.replan_lns_iterations if self.fresh_search else 0,
                time_limit=self.replan_time_limit_s,
            )
        self.tour = [v for v in plan.order[1:] if v != robot]
        if not self.tour and plan.complete and len(plan.path) > 1:
            # The plan's scans complete the episode on the way to its next viewpoint (its order is
            # cut there), so no viewpoint is left: head for where it completes instead of giving up.
            self.tour = [int(plan.path[-1])]
        self.planned = True
        self.fresh_search = False

    def _detour(self, robot: int) -> list[int]:
        """A known-free route for when the ground-truth path's next edge is not known free.

        Towards the next viewpoint (else the later ones, in tour order): among the nodes
        reachable through known space and strictly nearer to it than the robot (in
        ground-truth path length), the one that minimises known distance plus ground-truth
        distance on to the viewpoint; the strict progress rules out loops. If no viewpoint
        allows progress, the nearest node that sees frontier cells (as `nearest_frontier`);
        [] when there is none either.
        """
        assert self.graph is not None
        model = self.model
        dist_known, pred = self.graph.shortest_paths(int(model.nodes[robot]))
        reach = np.nonzero(np.isfinite(dist_known))[0]
        local = model.local[reach]
        ok = (local >= 0) & (local != robot)
        reach, local = reach[ok], local[ok]
        goal = -1
        for target in self.tour:
            to_target = model.dist[local, target]
            better = to_target < model.dist[robot, target] - 1e-3  # real progress, not a tie-break
            if better.any():
                cand, rest = reach[better], to_target[better]
                total = dist_known[cand] + rest
                goal = int(cand[np.lexsort((rest, np.round(total, 6)))[0]])
                break
        if goal < 0:
            useful = self.useful_nodes()
            useful = useful[
                np.isfinite(dist_known[useful]) & (model.local[useful] >= 0) & (model.local[useful] != robot)
            ]
            if useful.size == 0:
                return []
            goal = int(useful[np.argmin(dist_known[useful])])
        path = self.graph.path_from_predecessors(pred, goal)
        return [int(model.local[n]) for n in path[1:]]
