"""Min-max routes: targets split into one open route per robot so that the longest route is shortest.

`min_max_routes(distance, robots)` takes a square distance matrix whose first `robots` rows are
the robots' starts and whose other rows are the targets. Every target goes to exactly one
robot; a robot's route starts at its start and ends at its last target (open: nobody returns).
The objective is lexicographic: the longest route first, then the sum of all routes (of two
splits with the same longest route, the one that travels less overall).

Two solvers, by size:

- up to `exact_max` targets, exact dynamic programming: for every robot and every set of
  targets the shortest open path from its start through that set (Held-Karp), then the best
  split of the targets over the robots (a recursion over subsets). Small problems are the
  common case at a decision, and there OR-Tools' local search is not reliably optimal: a
  min-max objective is flat under single moves (most moves do not change the longest route);
- above it, OR-Tools routing: one vehicle per robot from its start to a shared dummy end at
  distance 0 from everything (open routes), arc costs the distances, and a travel dimension
  whose global span cost (the longest route, weighted far above the sum) makes the objective
  min-max. The first solution is deterministic (parallel cheapest insertion); local search
  improves it within `time_limit_ms`. With greedy descent (the default) the search stops at
  its first local optimum, so the result does not depend on the machine's speed unless the
  time limit cuts it short; guided local search uses the whole time limit.

Distances are metres; unreachable pairs (inf) cost as much as a detour through every finite
distance in the matrix, so a route uses one only when nothing else is left.
"""

from __future__ import annotations

import numpy as np

METAHEURISTICS = ("greedy_descent", "guided_local_search")
EXACT_MAX_LIMIT = 10  # the exact solver's subset recursion has 3^targets entries per robot
COST_SCALE = 100.0  # OR-Tools costs are integers: centimetres
SPAN_WEIGHT = 1000  # the longest route's weight in OR-Tools' objective, against the sum of routes


def min_max_routes(
    distance: np.ndarray,
    robots: int,
    time_limit_ms: int = 30,
    exact_max: int = 8,
    metaheuristic: str = "greedy_descent",
) -> list[list[int]]:
    """One open route per robot through all targets, minimising the longest route.

    `distance` is (robots + targets) square, metres: rows 0..robots-1 the robots' starts, the
    rest the targets (it is read as given, so it may be asymmetric). Returns, per robot, its
    targets in visiting order as target indices (0 = the matrix's row `robots`); a robot may get
    none. Exact up to `exact_max` targets; above, OR-Tools within `time_limit_ms` milliseconds.
    """
    d = _finite(np.asarray(distance, dtype=np.float64))
    robots = int(robots)
    if d.ndim != 2 or d.shape[0] != d.shape[1] or robots < 1 or d.shape[0] < robots:
        raise ValueError(f"distance must be square with at least {robots} robot rows, got shape {d.shape}")
    if not 0 <= exact_max <= EXACT_MAX_LIMIT:
        raise ValueError(f"exact_max must be in 0..{EXACT_MAX_LIMIT}, got {exact_max}")
    if metaheuristic not in METAHEURISTICS:
        raise ValueError(f"metaheuristic must be one of {', '.join(METAHEURISTICS)}, got {metaheuristic!r}")
    targets = d.shape[0] - robots
    if targets == 0:
        return [[] for _ in range(robots)]
    if targets <= exact_max:
        return _exact_routes(d, robots)
    return _ortools_routes(d, robots, int(time_limit_ms), metaheuristic)


def route_lengths(distance: np.ndarray, routes: list[list[int]]) -> list[float]:
    """Each robot's open route length along `distance` (laid out as `min_max_routes` takes it)."""
    d = np.asarray(distance, dtype=np.float64)
    robots = len(routes)
    lengths = []
    for robot, route in enumerate(routes):
        points = [robot] + [robots + t for t in route]
        lengths.append(float(sum(d[a, b] for a, b in zip(points[:-1], points[1:]))))
    return lengths


def _finite(d: np.ndarray) -> np.ndarray:
    """`d` with inf (unreachable) replaced by more than any route of finite steps can cost."""
    finite = np.isfinite(d)
    if finite.all():
        return d
    detour = float(d[finite].sum()) + 1.0 if finite.any() else 1.0
    return np.where(finite, d, detour)


# ------------------------------------------------------------------------- exact
def _exact_routes(d: np.ndarray, robots: int) -> list[list[int]]:
    """The lexicographic (longest, sum) optimum by dynamic programming over subsets of targets: the
    shortest longest route first, then the shortest sum of routes none longer than that."""
    targets = d.shape[0] - robots
    path = _open_paths(d, robots)  # (subsets, last target, robot)
    best = path.min(axis=1)  # shortest open path through each subset, per robot
    best[0] = 0.0
    # Every (set, part of it) pair once: target k is out of the set (digit 0), in the set but not
    # the part (1), or in the part (2), for the base-3 numbers 0 .. 3^targets - 1.
    weights = 1 << np.arange(targets)
    digits = (np.arange(3**targets)[:, None] // (3 ** np.arange(targets))[None, :]) % 3
    whole, part = (digits > 0) @ weights, (digits == 2) @ weights
    order = np.lexsort((part, whole))
    whole, part = whole[order], part[order]
    group_start = np.searchsorted(whole, np.arange(1 << targets))
    rest = whole ^ part
    # First the shortest longest route: longest[S] for robots 0..r through the targets S.
    longest = best[:, 0].copy()
    for robot in range(1, robots):
        longest = np.minimum.reduceat(np.maximum(best[part, robot], longest[rest]), group_start)
    bound = longest[-1] * (1 + 1e-12)
    # Then the shortest sum of routes none of which is longer: total[S] for robots 0..r, and
    # choices[r - 1][S] the part robot r takes (of equal sums, the first in part order).
    allowed = np.where(best <= bound, best, np.inf)
    total = allowed[:, 0].copy()
    choices: list[np.ndarray] = []
    for robot in range(1, robots):
        pair_total = allowed[part, robot] + total[rest]
        first = np.lexsort((np.arange(len(whole)), pair_total, whole))[group_start]
        choices.append(part[first])
        total = pair_total[first]
    routes: list[list[int]] = [[] for _ in range(robots)]
    remaining = (1 << targets) - 1
    for robot in range(robots - 1, 0, -1):
        taken = int(choices[robot - 1][remaining])
        routes[robot] = _path_order(d, path, robots, robot, taken)
        remaining ^= taken
    routes[0] = _path_order(d, path, robots, 0, remaining)
    return routes


def _open_paths(d: np.ndarray, robots: int) -> np.ndarray:
    """Held-Karp for every robot at once: [S, j, r] the shortest open path from robot r's start
    through exactly the targets in S, ending at target j (inf where j is not in S)."""
    targets = d.shape[0] - robots
    between = d[robots:, robots:]  # target -> target
    subsets = np.arange(1 << targets)
    bits = ((subsets[:, None] >> np.arange(targets)[None, :]) & 1).astype(bool)
    size = bits.sum(axis=1)
    single = 1 << np.arange(targets)
    path = np.full((1 << targets, targets, robots), np.inf)
    path[single, np.arange(targets), :] = d[:robots, robots:].T
    for count in range(2, targets + 1):
        layer = subsets[size == count]
        inside = bits[layer]  # (C, targets)
        before = np.where(inside, layer[:, None] ^ single[None, :], 0)  # the set before the last target k
        # via[c, k, j, r] = path[before[c, k], j, r] + between[j, k]
        via = path[before] + between.T[None, :, :, None]
        path[layer] = np.where(inside[:, :, None], via.min(axis=2), np.inf)
    return path


def _path_order(d: np.ndarray, path: np.ndarray, robots: int, robot: int, subset: int) -> list[int]:
    """The targets of `subset` in the order of robot `robot`'s shortest open path through them."""
    between = d[robots:, robots:]
    order: list[int] = []
    remaining, following = subset, None
    while remaining:
        costs = path[remaining, :, robot] + (0.0 if following is None else between[:, following])
        last = int(np.argmin(costs))
        order.append(last)
        remaining ^= 1 << last
        following = last
    order.reverse()
    return order


# ------------------------------------------------------------------------- OR-Tools
def _ortools_routes(d: np.ndarray, robots: int, time_limit_ms: int, metaheuristic: str) -> list[list[int]]:
    try:
        from ortools.constraint_solver import pywrapcp, routing_enums_pb2
    except ImportError as error:  # an optional dependency: the `team` extra
        raise ImportError(
            f"min-max routes through more targets than exact_max need OR-Tools: pip install ortools ({error})"
        ) from None

    nodes = d.shape[0]
    end = nodes  # the dummy end every route finishes at, at distance 0 from everything
    cost = np.zeros((nodes + 1, nodes + 1), dtype=np.int64)
    cost[:nodes, :nodes] = np.rint(d * COST_SCALE).astype(np.int64)
    np.fill_diagonal(cost, 0)
    manager = pywrapcp.RoutingIndexManager(nodes + 1, robots, list(range(robots)), [end] * robots)
    routing = pywrapcp.RoutingModel(manager)
    transit = routing.RegisterTransitMatrix(cost.tolist())
    routing.SetArcCostEvaluatorOfAllVehicles(transit)
    routing.AddDimension(transit, 0, int(cost.sum()) + 1, True, "travel")
    routing.GetDimensionOrDie("travel").SetGlobalSpanCostCoefficient(SPAN_WEIGHT)
    parameters = pywrapcp.DefaultRoutingSearchParameters()
    parameters.first_solution_strategy = routing_enums_pb2.FirstSolutionStrategy.PARALLEL_CHEAPEST_INSERTION
    parameters.local_search_metaheuristic = (
        routing_enums_pb2.LocalSearchMetaheuristic.GREEDY_DESCENT
        if metaheuristic == "greedy_descent"
        else routing_enums_pb2.LocalSearchMetaheuristic.GUIDED_LOCAL_SEARCH
    )
    parameters.time_limit.FromMilliseconds(max(1, time_limit_ms))
    solution = routing.SolveWithParameters(parameters)
    if solution is None:  # no solution within the time limit: cannot happen without constraints; be safe
        return _nearest_start_routes(d, robots)
    routes: list[list[int]] = []
    for vehicle in range(robots):
        route = []
        index = solution.Value(routing.NextVar(routing.Start(vehicle)))
        while not routing.IsEnd(index):
            route.append(manager.IndexToNode(index) - robots)
            index = solution.Value(routing.NextVar(index))
        routes.append(route)
    return routes


def _nearest_start_routes(d: np.ndarray, robots: int) -> list[list[int]]:
    """Every target to the robot whose start is nearest, each route in order of that distance."""
    targets = d.shape[0] - robots
    owner = np.argmin(d[:robots, robots:], axis=0)
    return [sorted((t for t in range(targets) if owner[t] == r), key=lambda t: d[r, robots + t]) for r in range(robots)]
