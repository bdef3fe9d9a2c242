"""Coordinated `guide_tsp` and `guide`: the global graph's frontier split into min-max routes.

Every robot runs its own single-robot planner (its own lattice graph, node predictor and global
graph, updated from its own observation). When a robot decides:

1. its region-evaluated global graph is built as `guide_tsp` builds it, and its frontier is
   clustered as `FrontierTour` clusters it (the cluster targets and weights);
2. the targets are split into one open route per robot minimising the longest route
   (`min_max_routes`), from every robot's position as the `TeamObservation` gives it, over
   shortest-path distances on the deciding robot's global graph (predicted nodes shape them,
   as they shape guide_tsp's tour). A robot's route is made `hysteresis` metres cheaper to
   start at its own current goal (as this robot knows the goals, `HeardGoals`), so that the
   split a robot computes agrees with the ones its teammates computed a moment before;
3. the deciding robot heads for the first target of its own route, one lattice step along the
   shortest path on the *known* graph, as guide_tsp does; with no route of its own (more robots
   than targets) it chooses as the coordinated greedy does, with its teammates' goals and the
   other routes' first targets as the goals it keeps away from. guide_tsp's cycle guard (`FrontierTour.keep_through_cycles`) still holds.

`guide` (its default mode, the tour vote) does the same, but step 3 is the tour vote's: the
first-target options are its own route's targets, scored as guide_tsp scores a tour's first
targets (weight per metre plus tour regret, over its own route), each score multiplied by
1 + `prior_weight` x how much the diffusion policy's samples head for it (`TourVote.target_votes`),
and the executed chunk is the tour vote's: the steps of the sample that heads for the chosen
target, followed while that target is still useful. The policy, graphs and T_o history are the
robot's own `TourVote` (`pipeline.planners.extensions.tour_vote`), used by composition. Its
block-model lookahead is single-robot: the team version refuses it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Annotated, Any, cast

import numpy as np
from scipy.sparse.csgraph import dijkstra

from pipeline.common.config import config_dataclass, text, whole
from pipeline.lattice.graph import LatticeGraph
from pipeline.lattice.tsp import path_length, tsp_path
from pipeline.planners.catalog import GuideOptions, GuideTspOptions, TourVoteOptions
from pipeline.planners.config import PlannerConfig, option
from pipeline.planners.extensions.tour_vote import TourVote
from pipeline.planners.guide.guide import drive
from pipeline.planners.guide.guide_tsp import FrontierTour, GuideTspPlanner
from pipeline.planners.registry import make_planner
from pipeline.planners.team.coordinated_greedy import base_options, burgard_choice
from pipeline.planners.team.heard_goals import HeardGoals
from pipeline.planners.team.min_max_routes import EXACT_MAX_LIMIT, METAHEURISTICS, min_max_routes
from pipeline.planners.team.registry import register_team_planner
from pipeline.planners.wrapper import innermost, layer
from pipeline.prediction.global_graph import KNOWN, GlobalGraph
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Planner, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.team import TeamObservation, TeamPlanner


@config_dataclass
class TeamRouteOptions(PlannerConfig):
    """How a coordinated tour team splits the frontier into min-max routes."""

    part = "the team's routes (ours)"

    routes_exact_max: Annotated[int, whole(0, EXACT_MAX_LIMIT)] = option(
        8, "min-max splits of up to this many targets are solved exactly; larger ones by OR-Tools"
    )
    routes_time_ms: Annotated[int, whole(1)] = option(
        30, "milliseconds OR-Tools may search a min-max split of more targets"
    )
    routes_search: Annotated[str, text(METAHEURISTICS)] = option(
        "greedy_descent",
        "OR-Tools' local search: greedy_descent (stops at its first local optimum) or "
        "guided_local_search (searches the whole time limit)",
    )


@config_dataclass
class CoordinatedGuideTspConfig(GuideTspOptions, TeamRouteOptions):
    description = (
        "guide_tsp per robot, the global graph's frontier clusters split into min-max routes over the "
        "team; each robot steps toward its own route's first target"
    )


@config_dataclass
class CoordinatedGuideConfig(TourVoteOptions, TeamRouteOptions):
    description = (
        "guide (tour vote) per robot, the global graph's frontier clusters split into min-max routes over "
        "the team; each robot's policy votes on its own route's first targets"
    )
    # guide_tsp's clusters (`TourVoteOptions`), not guide's single-node targets: the team splits its targets into
    # min-max routes, and one target per useful node would make that split a routing problem over all of them.

    def check(self) -> None:
        if self.mode != "tour":
            raise ValueError(f"the team guide splits the tour: mode must be tour, got {self.mode!r}")
        if self.lookahead:
            raise ValueError(
                f"the team guide has no lookahead (its rollouts are single-robot), got lookahead={self.lookahead}"
            )
        super().check()


@dataclass
class FrontierSplit:
    """One robot's view of the team's frontier: cluster targets and their min-max routes.

    `targets` (lattice ids) and `weights` are the clusters; `members` the robots in the split
    (robot indices, in index order) and `own` the deciding robot's place among them;
    `distance` the (members + targets) square matrix the split was solved on (hysteresis
    included), `target_rows` each target's global-graph distances to every global-graph row;
    `routes[i]` member i's targets (indices into `targets`) in visiting order.
    """

    targets: np.ndarray
    weights: np.ndarray
    members: list[int]
    own: int
    distance: np.ndarray
    target_rows: np.ndarray
    routes: list[list[int]]

    def own_route_targets(self) -> list[int]:
        """The deciding robot's route as lattice ids, in visiting order."""
        return [int(self.targets[t]) for t in self.routes[self.own]]

    def other_first_targets(self) -> list[int]:
        """The first target (lattice id) of every other robot's route that has one."""
        return [int(self.targets[route[0]]) for i, route in enumerate(self.routes) if route and i != self.own]


def known_row(global_graph: GlobalGraph, node: int) -> int | None:
    """The global-graph row of a known lattice node; None when the node is not a known free node."""
    known_ids = global_graph.lattice_ids[global_graph.types == KNOWN]
    row = int(np.searchsorted(known_ids, node))
    return row if row < len(known_ids) and known_ids[row] == node else None


def split_frontier(
    graph: LatticeGraph,
    global_graph: GlobalGraph,
    tour: FrontierTour,
    robot: int,
    dist: np.ndarray,
    candidates: np.ndarray,
    observation: TeamObservation,
    goals: list[int | None],
    options: TeamRouteOptions,
) -> FrontierSplit:
    """Cluster the deciding robot's reachable useful nodes as guide_tsp does and split the cluster
    targets into min-max routes for the team (steps 1-2 of the module's doc). `goals` are every
    robot's goals as the deciding robot knows them (its own: its previous first target)."""
    gg = global_graph
    known_ids = gg.lattice_ids[gg.types == KNOWN]
    utility = gg.utility[np.searchsorted(known_ids, candidates)]
    keep = tour.previous if tour.previous is not None and tour.previous in set(candidates.tolist()) else None
    targets, weights = tour.select_targets(graph, candidates, utility, dist, keep)
    members, rows = [], []
    for index, position in enumerate(observation.positions):
        if index == observation.robot:
            members.append(index)
            rows.append(known_row(gg, robot))
            continue
        # A teammate on its way between nodes: the node nearest to it, else the one it is heading for.
        row = known_row(gg, graph.nearest_node(position))
        heading = observation.targets[index]
        if row is None and heading is not None:
            row = known_row(gg, graph.nearest_node(heading))
        if row is not None:  # a teammate off this robot's known graph is left out of the split
            members.append(index)
            rows.append(row)
    points = np.concatenate([np.asarray(rows, dtype=np.int64), np.searchsorted(known_ids, targets)])
    reach = dijkstra(gg.adjacency, directed=False, indices=points)
    distance = reach[:, points]
    distance = np.minimum(distance, distance.T)
    count = len(members)
    xy = graph.node_world[targets]
    for i, index in enumerate(members):
        goal = goals[index]
        if goal is None:
            continue
        gap = np.hypot(*(xy - graph.node_world[goal]).T)
        nearest = int(np.argmin(gap))
        if gap[nearest] < tour.spread:  # the cluster the robot is heading for
            distance[i, count + nearest] = max(0.0, distance[i, count + nearest] - tour.hysteresis)
    routes = min_max_routes(distance, count, options.routes_time_ms, options.routes_exact_max, options.routes_search)
    return FrontierSplit(targets, weights, members, members.index(observation.robot), distance, reach[count:], routes)


def route_options(split: FrontierSplit, tour: FrontierTour, kept: int | None) -> dict:
    """The first-target options of the deciding robot's own route, scored as guide_tsp scores a
    tour's (`FrontierTour.first_target_scores`), over that route alone: the `first_k` best by
    weight per metre and the route's own first, each by weight per metre of (its distance +
    `beta` x how much longer the best open path through the route starting there is than the
    route). `kept` (the previous first target, a lattice id) is forgiven `hysteresis` metres.
    The keys are those `TourVote.target_votes` reads; the route must not be empty."""
    route = split.routes[split.own]
    count = len(split.members)
    points = [split.own] + [count + t for t in route]
    d = split.distance[np.ix_(points, points)]
    d = np.minimum(d, d.T)
    order = list(range(len(points)))
    length = path_length(d, order)
    weight = split.weights[route]
    options: dict[int, tuple[float, list[int]]] = {1: (np.inf, order)}
    if len(route) > 1:
        per_metre = weight / np.maximum(d[0, 1:], 1e-6)
        picked = set((np.argsort(-per_metre, kind="stable")[: tour.first_k] + 1).tolist()) | {1}
        kept_at = next((j + 1 for j, t in enumerate(route) if int(split.targets[t]) == kept), None)
        if kept_at is not None:
            picked.add(kept_at)
        options = {}
        for j in sorted(picked):
            if j == 1:
                tour_j, length_j = order, length
            else:
                rest = [i for i in order if i not in (0, j)]
                tail = tsp_path(d[np.ix_([j] + rest, [j] + rest)], None, tour.exact_max, tour.max_moves)
                tour_j = [0, j] + [rest[i - 1] for i in tail[1:]]
                length_j = path_length(d, tour_j)
            slack = tour.hysteresis if j == kept_at else 0.0
            options[j] = (weight[j - 1] / (d[0, j] + tour.beta * max(0.0, length_j - length - slack) + 1e-6), tour_j)
    firsts = sorted(options)
    return {
        "targets": split.targets[route],
        "weights": weight,
        "firsts": np.asarray([j - 1 for j in firsts], dtype=np.int64),
        "scores": np.asarray([options[j][0] for j in firsts]),
        "tours": [[int(split.targets[route[k - 1]]) for k in options[j][1][1:]] for j in firsts],
        "length": length,
        "option_distance": split.target_rows[route][[j - 1 for j in firsts]],
    }


class CoordinatedTourTeam(TeamPlanner):
    """One single-robot planner per robot (`base`: guide_tsp, or guide for the tour vote), the
    frontier split into min-max routes at every decision (the module's doc)."""

    base_name = "guide_tsp"
    base_config: type[PlannerConfig] = GuideTspOptions

    def __init__(self, config: TeamRouteOptions, objects: dict[str, Any] | None = None):
        self.config = config
        self.base = base_options(config, self.base_config)
        self.objects = dict(objects or {})  # an injected inpainter or policy (tests)
        self.planners: list[Planner] = []
        self.description = config.description
        self.last_decision: dict = {}

    def make_base(self) -> Planner:
        return make_planner(self.base_name, **self.base, **self.objects)

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int, robots: int) -> None:
        if len(self.planners) != robots:
            self.planners = [self.make_base() for _ in range(robots)]
        for k, planner in enumerate(self.planners):
            planner.reset(frame, protocol, seed * 1009 + k)
        self.goals = HeardGoals(robots)
        self.reach = float(protocol.sensor_range)

    def check_protocol(self, protocol: Protocol) -> None:
        (self.planners[0] if self.planners else self.make_base()).check_protocol(protocol)

    def known_goals(self, observation: TeamObservation, tour: FrontierTour) -> list[int | None]:
        """Every robot's goal as the deciding robot knows it: its teammates' heard, its own previous first target."""
        goals = self.goals.teammates_goals(observation)
        goals[observation.robot] = tour.previous
        return goals

    def next_target(
        self,
        split: FrontierSplit,
        graph: LatticeGraph,
        dist: np.ndarray,
        candidates: np.ndarray,
        goals: list[int | None],
    ) -> int:
        """The first target of the deciding robot's own route; with no route of its own (more
        robots than targets), the useful node the coordinated greedy would choose, its teammates'
        goals being the ones it knows (`goals`, its own entry aside) and the other routes' first
        targets (`burgard_choice`)."""
        route = split.own_route_targets()
        if route:
            return route[0]
        me = split.members[split.own]
        teammates = [g for i, g in enumerate(goals) if i != me and g is not None] + split.other_first_targets()
        return burgard_choice(graph.node_world, graph.utility, candidates, dist, teammates, self.reach)

    def plan(self, observation: TeamObservation) -> list[Waypoint]:
        planner = cast(GuideTspPlanner, innermost(self.planners[observation.robot]))
        own = observation.observation
        goals = self.known_goals(observation, planner.tour)
        graph, robot, dist, pred, candidates = planner.locate(own)
        if candidates.size == 0:
            self.goals.decided(observation, None)
            return []
        planner.update_global_graph(own)
        split = split_frontier(
            graph, planner.global_graph, planner.tour, robot, dist, candidates, observation, goals, self.config
        )
        first = self.next_target(split, graph, dist, candidates, goals)
        first = planner.tour.keep_through_cycles(own, robot, candidates, first)
        planner.tour.previous = first
        self.goals.decided(observation, first)
        self.last_decision = {
            "robot": observation.robot,
            "target": first,
            "targets": split.targets,
            "routes": split.routes,
            "members": split.members,
        }
        return planner.waypoints_along(graph.path_from_predecessors(pred, first))


class CoordinatedTourVoteTeam(CoordinatedTourTeam):
    """guide's tour vote per robot, on its own min-max route's first targets."""

    base_name = "guide"
    base_config = GuideOptions

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int, robots: int) -> None:
        super().reset(frame, protocol, seed, robots)
        self.votes = [tour_vote_of(planner) for planner in self.planners]  # after the reset: it may rebuild them

    def plan(self, observation: TeamObservation) -> list[Waypoint]:
        vote = self.votes[observation.robot]
        paper = vote.paper
        own = observation.observation
        goals = self.known_goals(observation, vote.tour)
        graph, robot, dist, pred, useful = paper.locate(own)
        if useful.size == 0:
            self.goals.decided(observation, None)
            return []
        target = vote.tour.previous
        queued = self.queued_step(vote, graph, robot, dist, useful)
        paper.update_global_graph(own)
        paper.observe(own.position)
        vote.decisions += 1
        if queued is not None:  # the rest of the last chunk, still on its way to a target
            vote.queue.pop(0)
            self.goals.decided(observation, target)
            return [cast(Waypoint, tuple(map(float, graph.node_world[queued])))]
        vote.queue = []
        split = split_frontier(
            graph, paper.global_graph, vote.tour, robot, dist, useful, observation, goals, self.config
        )
        deltas, expected = paper.sample_plans()
        paths = drive(graph, robot, deltas, expected)
        votes = None
        if split.routes[split.own]:
            options = route_options(split, vote.tour, vote.tour.previous)
            votes = vote.target_votes(robot, paths, options)
            scores = options["scores"] * (1.0 + vote.prior_weight * votes)
            target = cast(int, options["tours"][int(np.argmax(scores))][0])
        else:  # no route of its own: nothing to vote on
            target = self.next_target(split, graph, dist, useful, goals)
        target = vote.tour.keep_through_cycles(own, robot, useful, target)
        vote.tour.previous = target
        chunk = chunk_toward(graph, paths, target, paper.action_steps)
        if not chunk:
            vote.fallbacks += 1
            chunk = graph.path_from_predecessors(pred, target)[1 : 1 + paper.action_steps]
        vote.queue = chunk[1:]
        self.goals.decided(observation, target)
        self.last_decision = {
            "robot": observation.robot,
            "target": target,
            "targets": split.targets,
            "routes": split.routes,
            "members": split.members,
            "votes": votes,
        }
        return [cast(Waypoint, tuple(map(float, graph.node_world[chunk[0]])))]

    @staticmethod
    def queued_step(
        vote: TourVote, graph: LatticeGraph, robot: int, dist: np.ndarray, useful: np.ndarray
    ) -> int | None:
        """The next step of the last chunk while its target is still useful and the step still a known-free edge."""
        target = vote.tour.previous
        if not vote.queue or target is None or target not in set(useful.tolist()):
            return None
        step = int(vote.queue[0])
        return step if step in set(graph.neighbours(robot).tolist()) and dist[step] < np.inf else None


def chunk_toward(graph: LatticeGraph, paths: list[list[int]], target: int, action_steps: int) -> list[int]:
    """The tour vote's executed chunk: of the sampled plans (best progress toward `target` first),
    the first one's steps while each shortens the known-graph distance to `target` by its own
    length; [] when no plan's first step does."""
    to_target, _ = graph.shortest_paths(target)
    for path in sorted(paths, key=lambda q: to_target[q[min(len(q) - 1, action_steps)]]):
        run = []
        for node, following in zip(path[:action_steps], path[1 : action_steps + 1]):
            step = float(np.hypot(*(graph.node_world[following] - graph.node_world[node])))
            if not to_target[following] < to_target[node] - step + 1e-6:
                break
            run.append(following)
        if run:
            return run
    return []


def tour_vote_of(planner: Planner) -> TourVote:
    """The `TourVote` inside a built `guide` (under its model matching and trust wrappers)."""
    try:
        return layer(planner, TourVote)
    except TypeError:
        raise TypeError("the team guide needs guide in mode tour (the tour vote)") from None


@register_team_planner("guide_tsp", CoordinatedGuideTspConfig)
def build_coordinated_guide_tsp(config: CoordinatedGuideTspConfig) -> TeamPlanner:
    return CoordinatedTourTeam(config)


@register_team_planner("guide", CoordinatedGuideConfig)
def build_coordinated_guide(config: CoordinatedGuideConfig) -> TeamPlanner:
    return CoordinatedTourVoteTeam(config)
