"""Ground-truth coverage tours: the `Optimal` reference of docs/protocol.md and DARE's expert.

Everything here looks at the ground truth; it is the oracle side of the project.

- The ground-truth lattice graph is a `LatticeGraph` updated with a belief equal to the
  whole ground truth, so its edges are exactly the segments the motion rule would allow
  if everything were known.
- Each free lattice node reachable from the start gets the set of ground-truth free cells
  its scan reveals (the protocol sensor itself, `pipeline.world.sensor.scan`), stored as a sparse
  boolean matrix nodes x cells.
- A coverage plan is a list of viewpoints, ordered by an open TSP path from the robot over
  shortest-path distances on that graph, and expanded into the node-by-node path the robot
  drives. The robot scans at *every* node of that path, so plans are judged by simulating
  exactly those scans: a plan's length is the distance at which the done rule (ground-truth
  free cells not yet seen <= `done_unknown_cells`) is first met, and the path stops there.
- Viewpoints come from several randomised constructions (greedy set cover, then TSP
  order; or cheapest insertion of the best gain per metre); cover as needed, not more.
  Each is refined: viewpoints the path no longer needs are pruned (what the path sees on
  the way counts), viewpoints are moved to nearby nodes with a shorter detour, the rest is
  re-ordered by the TSP; the shortest plan wins and is polished by a few rounds of ruin
  and recreate.

`run_oracle_episode` runs any planner under the oracle's motion rule (segments free in the
ground truth, not necessarily in the belief: how `Optimal` may move), through the
simulator's own `oracle` rule, which `run_episode` applies to planners that declare
`ignores_motion_rule = True`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Sequence, cast

import numpy as np

from pipeline.lattice.tsp import EXACT_TSP_MAX_NODES, open_tsp_order
from pipeline.planners.references.coverage_model import CoverageModel, CoverageObjective, coverage_model
from pipeline.world.maps import GroundTruthMap
from pipeline.world.planner import Observation, Planner, reset_planner
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import Episode, EpisodeResult, replay, run_episode

DEFAULT_RESTARTS = 8
DEFAULT_LNS_ITERATIONS = 30
RESTART_METHODS = ("greedy", "insertion")
_EPS = 1e-9


# --------------------------------------------------------------------------- plans
@dataclass
class CoveragePlan:
    """Viewpoints in visiting order and the node path that visits them (local indices)."""

    order: list[int]  # robot first, then the viewpoints reached before completion
    path: list[int]  # node by node, robot first, cut where the episode completes
    length: float  # metres along `path`
    complete: bool  # whether scanning along `path` meets the done rule (then `path` stops there)
    remaining: int  # coverable cells still unseen at the end of `path`
    stats: dict = field(default_factory=dict)


def evaluate_order(objective: CoverageObjective, order: Sequence[int]) -> CoveragePlan:
    """Expand an order (robot first), simulate its scans and cut it where it completes."""
    model = objective.model
    path = model.expand(order)
    needed, length, remaining = objective.simulate(path)
    reached, pos = [int(order[0])], 0
    for v in order[1:]:
        pos += len(model.path(reached[-1], int(v))) - 1
        if pos > needed - 1:
            break
        reached.append(int(v))
    complete = remaining <= objective.slack and objective.achievable
    return CoveragePlan(reached, list(path[:needed]), length, complete, remaining)


def _better(a: CoveragePlan, b: CoveragePlan, allow_equal: bool = False) -> bool:
    """Complete beats incomplete; then fewer cells left (if incomplete); then shorter."""
    if a.complete != b.complete:
        return a.complete
    if not a.complete and a.remaining != b.remaining:
        return a.remaining < b.remaining
    if allow_equal:
        return a.length <= b.length + 1e-7
    return a.length < b.length - 1e-7


def greedy_cover(
    objective: CoverageObjective,
    robot: int,
    rng: np.random.Generator,
    tolerance: float = 0.0,
    distance_scale: float | None = None,
) -> list[int]:
    """A greedy set cover, stopping as soon as at most `slack` cells stay unseen.

    Each round takes a node among those whose score is within `tolerance` (a fraction) of
    the best, at random. The score is the number of new cells, divided by
    (1 + d / distance_scale) when `distance_scale` is set, d being the path distance to the
    nearest node already chosen (or the robot), which favours compact covers.
    """
    model = objective.model
    seen = objective.seen_by([robot])
    remaining = objective.total - int(np.bitwise_count(seen).sum())
    near = model.dist[robot].copy() if distance_scale else None
    chosen: list[int] = []
    while remaining > objective.slack:
        gains = objective.gains_after(seen).astype(np.float64)
        score = gains if near is None else gains / (1.0 + near / distance_scale)
        best = score.max()
        if best <= 0:
            break
        pool = np.nonzero(score >= best * (1.0 - tolerance) - _EPS)[0]
        pick = int(pool[rng.integers(len(pool))]) if len(pool) > 1 else int(pool[0])
        seen = seen | objective.bits[pick]
        remaining -= int(gains[pick])
        chosen.append(pick)
        if near is not None:
            np.minimum(near, model.dist[pick], out=near)
    return chosen


def insertion_cover(
    objective: CoverageObjective,
    robot: int,
    rng: np.random.Generator,
    tolerance: float = 0.0,
    exponent: float = 1.0,
    offset_m: float = 4.0,
    start_order: Sequence[int] | None = None,
) -> list[int]:
    """An order (robot first) built by cheapest insertion of the best gain per metre.

    Starts from `start_order` (robot first) when given. Each round scores every node by
    gain**exponent / (insertion cost + offset_m): the gain counts the cells the current
    path (scanning at every node) leaves unseen, capped at what is still needed; the
    insertion cost is the cheapest detour that puts the node into the order, or appends it.
    A node within `tolerance` of the best score is taken at random.
    """
    model = objective.model
    dist = model.dist
    order = [robot] if start_order is None else [int(v) for v in start_order]
    while True:
        seen = objective.seen_by(model.expand(order))
        need = objective.total - int(np.bitwise_count(seen).sum()) - objective.slack
        if need <= 0:
            return order
        gains = np.minimum(objective.gains_after(seen), need).astype(np.float64)
        cand = np.nonzero(gains > 0)[0]
        if cand.size == 0:
            return order
        o = np.asarray(order)
        append = dist[o[-1], cand][None, :]
        if len(o) > 1:
            into = dist[o[:-1, None], cand[None, :]] + dist[cand[None, :], o[1:, None]] - dist[o[:-1], o[1:]][:, None]
            costs = np.vstack([into, append])
        else:
            costs = append
        where = np.argmin(costs, axis=0)
        cost = costs[where, np.arange(len(cand))]
        score = gains[cand] ** exponent / (cost + offset_m)
        pool = np.nonzero(score >= score.max() * (1.0 - tolerance) - _EPS)[0]
        pick = int(pool[rng.integers(len(pool))]) if len(pool) > 1 else int(pool[0])
        order.insert(int(where[pick]) + 1, int(cand[pick]))


def _order_viewpoints(
    objective: CoverageObjective, robot: int, viewpoints: Sequence[int], exact_max_nodes: int
) -> list[int]:
    nodes = [robot] + [int(v) for v in dict.fromkeys(viewpoints) if int(v) != robot]
    perm = open_tsp_order(objective.model.dist[np.ix_(nodes, nodes)], exact_max_nodes)
    return [nodes[int(i)] for i in perm]


def viewpoint_detours(dist: np.ndarray, order: Sequence[int]) -> np.ndarray:
    """Per viewpoint order[i] (i >= 1): extra metres the order spends to pass through it."""
    o = np.asarray(order)
    prev, here = o[:-1], o[1:]
    nxt = np.append(o[2:], -1)
    has = nxt >= 0
    nxt_safe = np.where(has, nxt, 0)
    through = dist[prev, here] + np.where(has, dist[here, nxt_safe], 0.0)
    return through - np.where(has, dist[prev, nxt_safe], 0.0)


def prune_plan(objective: CoverageObjective, plan: CoveragePlan, deadline: float = np.inf) -> CoveragePlan:
    """Drop viewpoints the path does not need: without them it still completes, no later.

    What the whole path sees counts, intermediate nodes included, so a viewpoint whose
    cells are seen on the way through the others goes. Costliest detours are tried first.
    """
    improved = True
    while improved and len(plan.order) > 1 and time.perf_counter() < deadline:
        improved = False
        order = plan.order
        for i in np.argsort(viewpoint_detours(objective.model.dist, order), kind="stable")[::-1]:
            i = int(i) + 1
            trial = evaluate_order(objective, order[:i] + order[i + 1 :])
            if _better(trial, plan, allow_equal=True):
                plan, improved = trial, True
                break
    return plan


def relocate_plan(
    objective: CoverageObjective, plan: CoveragePlan, radius_m: float = 12.0, deadline: float = np.inf
) -> CoveragePlan:
    """Move single viewpoints to nodes within `radius_m` (graph metres) while that shortens the plan.

    Only nodes with a shorter detour than the viewpoint's are tried (typically: stop short
    of the end of a dead end when its cells are seen from nearer).
    """
    dist = objective.model.dist
    improved = True
    while improved and time.perf_counter() < deadline:
        improved = False
        order = plan.order
        for i in range(1, len(order)):
            a, v = order[i - 1], order[i]
            b = order[i + 1] if i + 1 < len(order) else None
            near = np.nonzero(dist[v] <= radius_m)[0]
            detour = dist[a, near] + (dist[near, b] if b is not None else 0.0)
            current = dist[a, v] + (dist[v, b] if b is not None else 0.0)
            keep = detour < current - 1e-7
            near, detour = near[keep], detour[keep]
            for w in near[np.argsort(detour, kind="stable")]:
                trial = evaluate_order(objective, order[:i] + [int(w)] + order[i + 1 :])
                if _better(trial, plan):
                    plan, improved = trial, True
                    break
            if improved or time.perf_counter() >= deadline:
                break
    return plan


def reinsert_plan(objective: CoverageObjective, plan: CoveragePlan, deadline: float = np.inf) -> CoveragePlan:
    """Move single viewpoints elsewhere in the order, judged by the simulated scans.

    The TSP orders by distance alone; here an order is judged by where the episode
    completes, which also depends on what each stretch of the path sees.
    """
    improved = True
    while improved and time.perf_counter() < deadline:
        improved = False
        order = plan.order
        for i in range(1, len(order)):
            rest = order[:i] + order[i + 1 :]
            for j in range(1, len(rest) + 1):
                if j == i:
                    continue
                trial = evaluate_order(objective, rest[:j] + [order[i]] + rest[j:])
                if _better(trial, plan):
                    plan, improved = trial, True
                    break
            if improved or time.perf_counter() >= deadline:
                break
    return plan


def refine(
    objective: CoverageObjective,
    order: Sequence[int],
    exact_max_nodes: int = EXACT_TSP_MAX_NODES,
    rounds: int = 4,
    deadline: float = np.inf,
    relocate_radius_m: float = 12.0,
    reorder_first: bool = True,
) -> CoveragePlan:
    """TSP-order the viewpoints, then prune, relocate and re-order while any of them helps.

    With `reorder_first` the given order competes with its TSP re-ordering (a re-ordered
    path may pass other nodes and see less). A plan that ends up incomplete is topped up
    by cheapest insertion and refined once more.
    """
    robot = int(order[0])
    plan = evaluate_order(objective, list(order))
    if reorder_first:
        reordered = evaluate_order(objective, _order_viewpoints(objective, robot, order[1:], exact_max_nodes))
        if _better(reordered, plan, allow_equal=True):
            plan = reordered
    plan = _refine_rounds(objective, plan, exact_max_nodes, rounds, deadline, relocate_radius_m)
    if not plan.complete and objective.need > 0:
        topped = insertion_cover(objective, robot, np.random.default_rng(0), start_order=plan.order)
        if len(topped) > len(plan.order):
            plan = _refine_rounds(
                objective, evaluate_order(objective, topped), exact_max_nodes, rounds, deadline, relocate_radius_m
            )
    return plan


def _refine_rounds(
    objective: CoverageObjective,
    plan: CoveragePlan,
    exact_max_nodes: int,
    rounds: int,
    deadline: float,
    relocate_radius_m: float,
) -> CoveragePlan:
    robot = plan.order[0]
    for _ in range(rounds):
        before = plan.length, plan.remaining
        plan = prune_plan(objective, plan, deadline)
        if relocate_radius_m > 0:
            plan = relocate_plan(objective, plan, relocate_radius_m, deadline)
        if time.perf_counter() >= deadline:
            break
        reordered = evaluate_order(objective, _order_viewpoints(objective, robot, plan.order[1:], exact_max_nodes))
        if _better(reordered, plan):
            plan = reordered
        elif (plan.length, plan.remaining) == before:
            break
    return plan


def ruin_and_recreate(
    objective: CoverageObjective,
    plan: CoveragePlan,
    rng: np.random.Generator,
    iterations: int,
    deadline: float = np.inf,
    exact_max_nodes: int = EXACT_TSP_MAX_NODES,
    relocate_radius_m: float = 12.0,
) -> CoveragePlan:
    """Large-neighbourhood search: drop 1-3 viewpoints, re-insert greedily, refine, keep if shorter."""
    robot = plan.order[0]
    for _ in range(iterations):
        k = len(plan.order) - 1
        if time.perf_counter() >= deadline or k < 1:
            break
        drop = int(rng.integers(1, min(3, k) + 1))
        if rng.random() < 0.5:  # a stretch of the tour
            first = int(rng.integers(1, k - drop + 2))
            removed = set(range(first, first + drop))
        else:
            removed = {int(i) for i in rng.choice(np.arange(1, k + 1), size=drop, replace=False)}
        kept = [v for i, v in enumerate(plan.order) if i not in removed]
        tolerance = float(rng.choice([0.0, 0.1, 0.2]))
        exponent = float(rng.choice([0.5, 1.0, 1.5, 2.0]))
        order = insertion_cover(objective, robot, rng, tolerance, exponent, start_order=kept)
        trial = refine(objective, order, exact_max_nodes, deadline=deadline, relocate_radius_m=relocate_radius_m)
        if _better(trial, plan):
            plan = trial
    return plan


def plan_coverage(
    model: CoverageModel,
    robot: int,
    uncovered: np.ndarray,
    rng: np.random.Generator,
    restarts: int = DEFAULT_RESTARTS,
    warm_order: Sequence[int] | None = None,
    lns_iterations: int = DEFAULT_LNS_ITERATIONS,
    exact_max_nodes: int = EXACT_TSP_MAX_NODES,
    time_limit: float | None = None,
    methods: Sequence[str] = RESTART_METHODS,
    relocate_radius_m: float = 12.0,
) -> CoveragePlan:
    """The shortest plan from local node `robot` that sees enough of the `uncovered` cells.

    `uncovered` (mask over the model's columns) should exclude what the robot has already
    seen, its own scan included. `warm_order` (viewpoints, e.g. the previous tour) is refined
    without re-ordering and competes with `restarts` fresh constructions cycling through
    `methods`: "greedy" (set cover, then TSP order) and "insertion" (cheapest insertion by
    gain per metre). The first restart of each method is its plain version (ties at
    random); later ones draw a score tolerance and a distance scale or gain exponent. The
    best is polished by re-insertion and `lns_iterations` rounds of ruin and recreate.
    The result depends only on the inputs and `rng`, unless `time_limit` (seconds, a
    safety net) cuts the search short.
    """
    deadline = time.perf_counter() + time_limit if time_limit else np.inf
    objective = CoverageObjective(model, uncovered)
    log: list[tuple[str, float]] = []
    best: CoveragePlan | None = None
    if warm_order is not None:
        warm = [robot] + [int(v) for v in warm_order if int(v) != robot]
        best = refine(
            objective,
            warm,
            exact_max_nodes,
            deadline=deadline,
            relocate_radius_m=relocate_radius_m,
            reorder_first=False,
        )
        log.append(("warm", best.length))
    for r in range(restarts):
        if best is not None and time.perf_counter() >= deadline:
            break
        method = methods[r % len(methods)]
        plain = r < len(methods)
        tolerance = 0.0 if plain else float(rng.choice([0.0, 0.1, 0.2, 0.3]))
        if method == "greedy":
            scale = None if plain else (float(rng.choice([0.0, 10.0, 20.0, 40.0, 80.0])) or None)
            order = [robot] + greedy_cover(objective, robot, rng, tolerance, scale)
        elif method == "insertion":
            exponent = 1.0 if plain else float(rng.choice([0.5, 1.0, 1.5, 2.0]))
            order = insertion_cover(objective, robot, rng, tolerance, exponent)
        else:
            raise ValueError(f"unknown restart method {method!r}; choose from {RESTART_METHODS}")
        plan = refine(objective, order, exact_max_nodes, deadline=deadline, relocate_radius_m=relocate_radius_m)
        log.append((method, plan.length))
        if best is None or _better(plan, best):
            best = plan
    if best is None:
        best = evaluate_order(objective, [robot])
    if best.complete and len(best.order) > 2 and lns_iterations > 0:
        best = reinsert_plan(objective, best, deadline)
        best = ruin_and_recreate(objective, best, rng, lns_iterations, deadline, exact_max_nodes, relocate_radius_m)
        log.append(("lns", best.length))
    best.stats["search"] = log
    return best


def uncovered_after_scan(model: CoverageModel, robot: int, known_free: np.ndarray | None = None) -> np.ndarray:
    """Coverable cells not known free and not revealed by a scan at local node `robot`."""
    uncovered = model.uncovered(known_free)
    uncovered[model.row(robot)] = False
    return uncovered


def choose_viewpoints(
    model: CoverageModel,
    robot: int | None = None,
    known_free: np.ndarray | None = None,
    seed: int = 0,
    restarts: int = DEFAULT_RESTARTS,
    lns_iterations: int = DEFAULT_LNS_ITERATIONS,
) -> list[int]:
    """Lattice node ids of the best plan's viewpoints, in visiting order.

    The robot's own scan (at the start if `robot`, a lattice node id, is None) is taken as
    given; coverage is complete when at most `done_unknown_cells` ground-truth free cells
    stay unseen (cover as needed, not more).
    """
    local = model.start if robot is None else int(model.local[robot])
    uncovered = uncovered_after_scan(model, local, known_free)
    plan = plan_coverage(model, local, uncovered, np.random.default_rng(seed), restarts, lns_iterations=lns_iterations)
    return [int(model.nodes[v]) for v in plan.order[1:]]


def coverage_plan(
    ground_truth: GroundTruthMap,
    protocol: Protocol,
    seed: int = 0,
    restarts: int = DEFAULT_RESTARTS,
    lns_iterations: int = DEFAULT_LNS_ITERATIONS,
    time_limit: float | None = None,
) -> tuple[CoverageModel, CoveragePlan]:
    """The ground-truth coverage plan from the start (the start's scan already given)."""
    model = coverage_model(ground_truth, protocol)
    uncovered = uncovered_after_scan(model, model.start)
    plan = plan_coverage(
        model,
        model.start,
        uncovered,
        np.random.default_rng(seed),
        restarts,
        lns_iterations=lns_iterations,
        time_limit=time_limit,
    )
    return model, plan


def coverage_tour(
    ground_truth: GroundTruthMap,
    protocol: Protocol,
    seed: int = 0,
    restarts: int = DEFAULT_RESTARTS,
    lns_iterations: int = DEFAULT_LNS_ITERATIONS,
    time_limit: float | None = None,
) -> list[tuple[float, float]]:
    """The `Optimal` tour: lattice waypoints in metres, node by node, the start (0, 0) first.

    Consecutive waypoints are joined by ground-truth graph edges; the tour ends where the
    episode completes (or, if the map cannot be completed, once all it can see is seen).
    """
    model, plan = coverage_plan(ground_truth, protocol, seed, restarts, lns_iterations, time_limit)
    return [cast("tuple[float, float]", tuple(map(float, model.world[v]))) for v in plan.path]


# --------------------------------------------------------------------------- oracle runs
class _OracleRule:
    """Wraps a planner so that the simulator applies the oracle motion rule to its moves."""

    ignores_motion_rule = True
    uses_ground_truth = True  # it hands the ground truth on only to a planner that is an oracle itself

    def __init__(self, planner: Planner):
        self.planner = planner
        self.name = getattr(planner, "name", "") or type(planner).__name__

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        reset_planner(self.planner, ground_truth, protocol, seed)

    def plan(self, observation: Observation) -> list[tuple[float, float]]:
        return self.planner.plan(observation)


def run_oracle_episode(
    ground_truth: GroundTruthMap,
    planner: Planner,
    protocol: Protocol,
    seed: int = 0,
    on_step: Callable[[Episode], None] | None = None,
) -> EpisodeResult:
    """`run_episode` under the oracle's motion rule, whatever the planner declares.

    Segments must be free in the ground truth (observed or not) instead of known free in
    the belief; lattice and in-grid checks, sensing and the done rule are the simulator's.
    """
    return run_episode(ground_truth, _OracleRule(planner), protocol, seed, on_step)  # type: ignore[arg-type]


def replay_oracle(
    ground_truth: GroundTruthMap, waypoints: Sequence[Sequence[float]], protocol: Protocol
) -> EpisodeResult:
    """Replay a tour (first row the start) under the oracle rule; distance at completion."""
    return replay(ground_truth, waypoints, protocol, planner_name="optimal", oracle=True)
