"""Team `optimal`: the ground-truth coverage reference for N robots (an oracle).

At a team's first decision (time 0, when every robot's start is known) it plans on the ground
truth, with the single-robot `optimal`'s pieces (`pipeline.planners.references.coverage`):

1. viewpoints: the single `optimal`'s plan from the first robot's start, every start's scan
   given; its viewpoints in visiting order, plus the node where its path completes when that
   path is cut on the way to a viewpoint;
2. the viewpoints are split into one open route per robot minimising the longest route
   (`min_max_routes`) over ground-truth shortest-path distances, and each route is expanded
   into the node-by-node path its robot drives;
3. the plan is judged as the team episode runs it: every robot scans at every node of its path,
   arrivals in time order, and the team's time is the first arrival at which the done rule
   holds. The single plan dropped viewpoints whose cells its one path saw on the way; split
   paths pass elsewhere, so when the split leaves too much unseen, a greedy set cover of what
   is left is added to the viewpoints and the split is solved again (and if a few such rounds
   do not complete, the viewpoints of a cover that alone sees everything are added, which
   must). Then viewpoints no path needs any more are pruned one at a time while the team's
   time does not grow. The single `optimal`'s own path for the first robot (the others
   staying put) competes, so the team reference is never slower than the single one.

Each robot gets its whole path at its first decision and nothing after it, as the single
`optimal` does. Like it, the team moves through ground-truth free cells not yet seen
(`ignores_motion_rule = True`): the episode and `replay_team(..., oracle=True)` check its
segments against the ground truth. The plan ignores communication: the oracle knows everything.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Annotated, cast

import numpy as np

from pipeline.common.config import config_dataclass, whole
from pipeline.planners.config import option
from pipeline.planners.references.coverage import greedy_cover, plan_coverage, viewpoint_detours
from pipeline.planners.references.coverage_model import CoverageModel, CoverageObjective, coverage_model
from pipeline.planners.references.coverage_planners import OptimalConfig
from pipeline.planners.team.coordinated_tour import TeamRouteOptions
from pipeline.planners.team.min_max_routes import min_max_routes
from pipeline.planners.team.registry import register_team_planner
from pipeline.world.maps import GroundTruthMap
from pipeline.world.planner import Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.team import TeamObservation, TeamPlanner

_EPS = 1e-7


@config_dataclass
class TeamOptimalConfig(OptimalConfig, TeamRouteOptions):
    description = (
        "oracle: the single optimal's ground-truth viewpoints split into min-max routes for the team, "
        "the team reference"
    )

    # A one-off split at reset, not one per decision: OR-Tools may take longer than a tour team's.
    routes_time_ms: Annotated[int, whole(1)] = option(
        1000, "milliseconds OR-Tools may search a min-max split of more targets"
    )
    top_up_rounds: Annotated[int, whole(0)] = option(
        3,
        "times a split that leaves too much unseen gets a greedy cover of the rest before the viewpoints of a "
        "full cover are added",
    )


@dataclass
class TeamCoveragePlan:
    """Each robot's route (local viewpoints in visiting order) and node path, and how the team fares.

    `makespan` is the team's time (metres) at the first arrival where the done rule holds, inf
    when the paths never meet it; `remaining` the coverable cells left unseen at the end.
    """

    routes: list[list[int]]
    paths: list[list[int]]
    makespan: float
    remaining: int

    @property
    def complete(self) -> bool:
        return np.isfinite(self.makespan)

    def better_than(self, other: "TeamCoveragePlan | None") -> bool:
        """Complete first, then the sooner done (of incomplete plans, the one leaving fewer cells unseen)."""
        if other is None:
            return True
        if self.complete != other.complete:
            return self.complete
        if not self.complete:
            return self.remaining < other.remaining
        return self.makespan < other.makespan - _EPS


def team_makespan(objective: CoverageObjective, paths: list[list[int]]) -> tuple[float, int]:
    """(team's time when the done rule first holds, coverable cells unseen at the end): every
    robot scans at every node of its path, at the time it arrives (metres driven), the starts at 0.

    The time is inf when the paths never meet the done rule.
    """
    model = objective.model
    times, nodes = [], []
    for path in paths:
        if not path:
            continue
        steps = np.diff(model.world[np.asarray(path)], axis=0)
        arrivals = np.concatenate([[0.0], np.cumsum(np.hypot(steps[:, 0], steps[:, 1]))])
        times.append(arrivals)
        nodes.append(np.asarray(path, dtype=np.int64))
    if not nodes:
        return float("inf"), objective.total
    when, where = np.concatenate(times), np.concatenate(nodes)
    order = np.argsort(when, kind="stable")
    when, where = when[order], where[order]
    seen = np.bitwise_or.accumulate(objective.bits[where], axis=0)
    remaining = objective.total - np.bitwise_count(seen).sum(axis=1).astype(np.int64)
    done = (remaining <= objective.slack) & objective.achievable
    if not done.any():
        return float("inf"), int(remaining[-1])
    # Every start is scanned before anyone moves: done among the starts is done at time 0.
    first = int(np.argmax(done))
    return float(when[first]), int(remaining[first])


def split_viewpoints(
    model: CoverageModel,
    objective: CoverageObjective,
    starts: list[int],
    viewpoints: list[int],
    config: TeamOptimalConfig,
) -> TeamCoveragePlan:
    """Viewpoints split into min-max routes from the starts (local nodes), expanded and judged."""
    targets = [v for v in dict.fromkeys(viewpoints) if v not in starts]
    nodes = starts + targets
    distance = model.dist[np.ix_(nodes, nodes)]
    split = min_max_routes(distance, len(starts), config.routes_time_ms, config.routes_exact_max, config.routes_search)
    routes = [[targets[t] for t in route] for route in split]
    return judge_routes(model, objective, starts, routes)


def judge_routes(
    model: CoverageModel, objective: CoverageObjective, starts: list[int], routes: list[list[int]]
) -> TeamCoveragePlan:
    paths = [model.expand([start] + route) for start, route in zip(starts, routes)]
    makespan, remaining = team_makespan(objective, paths)
    return TeamCoveragePlan(routes, paths, makespan, remaining)


def unseen_after(model: CoverageModel, paths: list[list[int]]) -> np.ndarray:
    """Mask over the model's columns: coverable cells no scan along `paths` reveals."""
    nodes = np.unique(np.concatenate([np.asarray(p, dtype=np.int64) for p in paths if p]))
    unseen = np.ones(len(model.cells), dtype=bool)
    unseen[model.cover[nodes].indices] = False
    return unseen


def prune_routes(
    model: CoverageModel,
    objective: CoverageObjective,
    starts: list[int],
    plan: TeamCoveragePlan,
    deadline: float = np.inf,
) -> TeamCoveragePlan:
    """Drop viewpoints while the team still completes no later (what every path sees on the way
    counts); within a route, the costliest detours are tried first."""
    improved = True
    while improved and plan.complete and time.perf_counter() < deadline:
        improved = False
        for robot, route in enumerate(plan.routes):
            if not route:
                continue
            order = [starts[robot]] + route
            for i in np.argsort(viewpoint_detours(model.dist, order), kind="stable")[::-1]:
                routes = [list(r) for r in plan.routes]
                del routes[robot][int(i)]
                trial = judge_routes(model, objective, starts, routes)
                if trial.complete and trial.makespan <= plan.makespan + _EPS:
                    plan, improved = trial, True
                    break
            if improved:
                break
    return plan


def covering_split(
    model: CoverageModel,
    objective: CoverageObjective,
    starts: list[int],
    viewpoints: list[int],
    config: TeamOptimalConfig,
    rng: np.random.Generator,
) -> TeamCoveragePlan:
    """The min-max split of `viewpoints`, topped up until the team's paths meet the done rule.

    Up to `config.top_up_rounds` times, a greedy set cover of what the split's paths leave unseen
    is added and the split solved again; if that does not complete, the viewpoints of a greedy
    cover of every cell the starts leave unseen are added, whose own scans meet the done rule
    whatever the paths between them see (unless the map cannot be completed at all).
    """
    viewpoints = list(viewpoints)
    plan = split_viewpoints(model, objective, starts, viewpoints, config)
    for _ in range(config.top_up_rounds):
        if plan.complete:
            return plan
        rest = CoverageObjective(model, unseen_after(model, plan.paths))
        viewpoints += greedy_cover(rest, starts[0], rng)
        plan = split_viewpoints(model, objective, starts, viewpoints, config)
    if not plan.complete:
        uncovered = unseen_after(model, [[start] for start in starts])
        viewpoints += greedy_cover(CoverageObjective(model, uncovered), starts[0], rng)
        plan = split_viewpoints(model, objective, starts, viewpoints, config)
    return plan


def plan_team_coverage(
    model: CoverageModel, starts: list[int], config: TeamOptimalConfig, seed: int = 0
) -> TeamCoveragePlan:
    """The team reference's routes from the starts (local nodes of `model`, one per robot)."""
    deadline = time.perf_counter() + config.time_limit_s if config.time_limit_s else np.inf
    objective = CoverageObjective(model, np.ones(len(model.cells), dtype=bool))
    uncovered = model.uncovered()
    for start in starts:
        uncovered[model.row(start)] = False
    single = plan_coverage(
        model,
        starts[0],
        uncovered,
        np.random.default_rng(seed),
        config.restarts,
        lns_iterations=config.lns_iterations,
        time_limit=config.time_limit_s,
    )
    viewpoints = [int(v) for v in single.order[1:]]
    if len(single.path) > 1 and int(single.path[-1]) not in viewpoints:
        viewpoints.append(int(single.path[-1]))  # its path is cut on the way to the next viewpoint
    plan = covering_split(model, objective, starts, viewpoints, config, np.random.default_rng(seed))
    plan = prune_routes(model, objective, starts, plan, deadline)
    # The single `optimal`'s own path for the first robot, the others staying at their starts.
    path = [int(v) for v in single.path]
    alone = [path] + [[start] for start in starts[1:]]
    own = TeamCoveragePlan(
        [[int(v) for v in single.order[1:]]] + [[] for _ in starts[1:]], alone, *team_makespan(objective, alone)
    )
    if own.better_than(plan):
        plan = own
    return plan


class TeamOptimal(TeamPlanner):
    """The ground-truth team coverage reference: min-max routes through the single `optimal`'s
    viewpoints, each robot's whole path handed over at its first decision (oracle motion rule)."""

    description = TeamOptimalConfig.description
    uses_ground_truth = True
    ignores_motion_rule = True

    def __init__(self, config: TeamOptimalConfig = TeamOptimalConfig()):
        self.config = config
        self.plan_: TeamCoveragePlan | None = None

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int, robots: int) -> None:  # type: ignore[override]  # an oracle: reset with the map itself
        self.ground_truth, self.protocol, self.seed, self.robots = ground_truth, protocol, seed, robots
        self.model = coverage_model(ground_truth, protocol)
        self.plan_ = None
        self.paths: list[list[Waypoint]] = [[] for _ in range(robots)]
        self.sent = [False] * robots

    def plan(self, observation: TeamObservation) -> list[Waypoint]:
        if self.plan_ is None:
            # Planned at the first decision, not in reset: reset does not get the starts, the first
            # decision's positions are all of them (nobody has arrived anywhere yet).
            self._plan_team(list(observation.positions))
        robot = observation.robot
        if self.sent[robot]:
            return []  # its path is driven and the episode is not complete: nothing left to cover
        self.sent[robot] = True
        return list(self.paths[robot][1:])

    def _plan_team(self, positions: list[Waypoint]) -> None:
        model = self.model
        local = [int(model.local[model.graph.nearest_node(p)]) for p in positions]
        # A robot starting where the map's start cannot reach (not in the model) gets no route.
        planned = [k for k, node in enumerate(local) if node >= 0]
        if not planned:
            self.plan_ = TeamCoveragePlan([[] for _ in positions], [[] for _ in positions], float("inf"), 0)
            return
        team = plan_team_coverage(model, [local[k] for k in planned], self.config, self.seed)
        routes: list[list[int]] = [[] for _ in positions]
        paths: list[list[int]] = [[] for _ in positions]
        for k, route, path in zip(planned, team.routes, team.paths):
            routes[k], paths[k] = route, path
        self.plan_ = TeamCoveragePlan(routes, paths, team.makespan, team.remaining)
        self.paths = [[cast(Waypoint, tuple(map(float, model.world[v]))) for v in path] for path in paths]

    @property
    def makespan_m(self) -> float:
        """The planned team time (metres) at which the done rule holds; inf before planning or when it never does."""
        return float("inf") if self.plan_ is None else self.plan_.makespan


@register_team_planner("optimal", TeamOptimalConfig)
def build_team_optimal(config: TeamOptimalConfig) -> TeamPlanner:
    return TeamOptimal(config)
