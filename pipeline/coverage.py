"""Ground-truth coverage tours: the `Optimal` reference of PROTOCOL.md and DARE's expert.

Everything here looks at the ground truth; it is the oracle side of the project.

- The ground-truth lattice graph is a `LatticeGraph` updated with a belief equal to the
  whole ground truth, so its edges are exactly the segments the motion rule would allow
  if everything were known.
- Each free lattice node reachable from the start gets the set of ground-truth free cells
  its scan reveals (the protocol sensor itself, `pipeline.sensor.scan`), stored as a sparse
  boolean matrix nodes x cells.
- A coverage plan is a list of viewpoints, ordered by an open TSP path from the robot over
  shortest-path distances on that graph, and expanded into the node-by-node path the robot
  drives. The robot scans at *every* node of that path, so plans are evaluated by
  simulating exactly those scans: the plan's length is the distance at which the done rule
  (ground-truth free cells not yet seen <= `done_unknown_cells`) is first met.
- Viewpoints come from several randomised greedy set covers (cover as needed, not more);
  each is ordered, then pruned with what the whole path sees (a viewpoint whose removal
  still completes the episode, no later, goes), re-ordered, and the shortest wins.

`run_oracle_episode` runs a planner with the oracle's motion rule (segments must be free in
the ground truth, not in the belief), which is how `Optimal` is allowed to move.
"""

from __future__ import annotations

import hashlib
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Callable, Sequence

import numpy as np
from python_tsp.exact import solve_tsp_dynamic_programming
from python_tsp.heuristics import solve_tsp_lin_kernighan
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from pipeline.geometry import segment_is_known_free
from pipeline.graph import LatticeGraph, LatticeSpec
from pipeline.maps import GroundTruthMap
from pipeline.protocol import Protocol
from pipeline.sensor import FREE, OCCUPIED, scan
from pipeline.simulator import Episode, EpisodeResult, MotionError

if TYPE_CHECKING:
    from pipeline.planners.base import Planner

EXACT_TSP_MAX_NODES = 10  # DP is ~10 ms at 10 nodes, ~70 ms at 12 and doubles per node
_EPS = 1e-9


# --------------------------------------------------------------------------- the model
def lattice_spec(ground_truth: GroundTruthMap, protocol: Protocol) -> LatticeSpec:
    """The lattice every planner uses on this map (as `GraphPlanner.reset` builds it)."""
    return LatticeSpec(
        shape=ground_truth.shape,
        start_cell=ground_truth.start_cell,
        cell_size=protocol.cell_size,
        node_resolution=protocol.node_resolution,
        utility_range=protocol.utility_range,
        region_size=protocol.region_size,
    )


def ground_truth_graph(ground_truth: GroundTruthMap, protocol: Protocol) -> LatticeGraph:
    """The lattice graph of a belief that equals the ground truth: edges = free segments."""
    graph = LatticeGraph(lattice_spec(ground_truth, protocol))
    belief = np.where(ground_truth.free, FREE, OCCUPIED).astype(np.uint8)
    graph.update(belief, None)
    return graph


def node_cell_matrix(
    ground_truth: GroundTruthMap, graph: LatticeGraph, nodes: np.ndarray, protocol: Protocol
) -> csr_matrix:
    """Boolean nodes x cells matrix: row k holds the free cells a scan at `nodes[k]` reveals."""
    rows, cols = [], []
    for k, node in enumerate(nodes):
        cells = scan(ground_truth.free, tuple(int(c) for c in graph.node_cells[node]), protocol.sensor_range_cells).free
        rows.append(np.full(cells.size, k, dtype=np.int64))
        cols.append(cells.astype(np.int64))
    r = np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)
    c = np.concatenate(cols) if cols else np.zeros(0, dtype=np.int64)
    data = np.ones(r.size, dtype=bool)
    return csr_matrix((data, (r, c)), shape=(len(nodes), ground_truth.free.size))


class CoverageModel:
    """Ground-truth lattice graph, per-node scans and all-pairs shortest paths of one map.

    Nodes are renumbered locally: local index k is lattice node `nodes[k]`, the nodes
    reachable from the start on the ground-truth graph. Cells are renumbered too: column j
    is flat grid cell `cells[j]`, the free cells that some reachable node's scan reveals.
    """

    def __init__(self, ground_truth: GroundTruthMap, protocol: Protocol):
        self.ground_truth = ground_truth
        self.protocol = protocol
        self.graph = ground_truth_graph(ground_truth, protocol)
        graph = self.graph
        self.start_node = graph.nearest_node((0.0, 0.0))
        reach = np.isfinite(graph.shortest_paths(self.start_node)[0])
        self.nodes = np.nonzero(reach)[0]
        self.local = np.full(graph.node_count, -1, dtype=np.int64)
        self.local[self.nodes] = np.arange(len(self.nodes))
        self.start = int(self.local[self.start_node])
        adjacency = graph.adjacency()[self.nodes][:, self.nodes]
        self.dist, pred = dijkstra(adjacency, directed=False, return_predecessors=True)
        self.pred = pred.astype(np.int64)
        full = node_cell_matrix(ground_truth, graph, self.nodes, protocol)
        self.cells = np.unique(full.indices)
        self.column = np.full(ground_truth.free.size, -1, dtype=np.int64)
        self.column[self.cells] = np.arange(len(self.cells))
        self.cover = full[:, self.cells].tocsr()
        self.cover.sort_indices()
        self.cover_csc = self.cover.tocsc()
        self.cover_csc.sort_indices()
        self.free_cell_count = ground_truth.free_cell_count
        self.world = graph.node_world[self.nodes].astype(np.float64)
        self.node_cells = graph.node_cells[self.nodes]
        self._paths: dict[tuple[int, int], tuple[int, ...]] = {}

    @property
    def node_count(self) -> int:
        return len(self.nodes)

    def row(self, k: int) -> np.ndarray:
        """Columns (local cells) revealed by a scan at local node k."""
        return self.cover.indices[self.cover.indptr[k] : self.cover.indptr[k + 1]]

    def path(self, a: int, b: int) -> tuple[int, ...]:
        """Local nodes of the shortest ground-truth path from a to b, both included."""
        key = (a, b)
        cached = self._paths.get(key)
        if cached is None:
            out = [b]
            while out[-1] != a:
                out.append(int(self.pred[a, out[-1]]))
            cached = tuple(reversed(out))
            self._paths[key] = cached
        return cached

    def expand(self, order: Sequence[int]) -> list[int]:
        """Node-by-node path visiting `order` (first entry: where the robot is)."""
        out = [int(order[0])]
        for a, b in zip(order[:-1], order[1:]):
            out.extend(self.path(int(a), int(b))[1:])
        return out

    def uncovered(self, known_free: np.ndarray | None = None) -> np.ndarray:
        """Mask over columns of the coverable cells not yet known free (all if None)."""
        if known_free is None:
            return np.ones(len(self.cells), dtype=bool)
        return ~known_free.reshape(-1)[self.cells]

    def slack(self, uncovered: np.ndarray) -> int:
        """How many coverable cells may stay unseen when the episode is complete.

        The done rule counts every ground-truth free cell; cells no reachable scan reveals
        are lost anyway. If they alone exceed the allowance, everything coverable is needed.
        """
        uncoverable = self.free_cell_count - len(self.cells)
        return max(0, self.protocol.done_unknown_cells - uncoverable)


_MODEL_CACHE: "OrderedDict[tuple, CoverageModel]" = OrderedDict()
_MODEL_CACHE_SIZE = 4


def coverage_model(ground_truth: GroundTruthMap, protocol: Protocol) -> CoverageModel:
    """The `CoverageModel` of a map, cached (a few recent maps) so planners share it."""
    digest = hashlib.sha1(np.ascontiguousarray(ground_truth.free).tobytes()).hexdigest()
    key = (digest, ground_truth.shape, tuple(ground_truth.start_cell), ground_truth.cell_size, protocol)
    model = _MODEL_CACHE.get(key)
    if model is None:
        model = CoverageModel(ground_truth, protocol)
        _MODEL_CACHE[key] = model
        while len(_MODEL_CACHE) > _MODEL_CACHE_SIZE:
            _MODEL_CACHE.popitem(last=False)
    else:
        _MODEL_CACHE.move_to_end(key)
    return model


# --------------------------------------------------------------------------- set cover
def _rows_of_columns(model: CoverageModel, columns: np.ndarray) -> np.ndarray:
    """All local nodes (with repetition) whose scan reveals each of `columns`."""
    csc = model.cover_csc
    starts = csc.indptr[columns]
    lengths = csc.indptr[columns + 1] - starts
    total = int(lengths.sum())
    if total == 0:
        return np.zeros(0, dtype=np.int64)
    offsets = np.repeat(starts - np.concatenate([[0], np.cumsum(lengths)[:-1]]), lengths)
    return csc.indices[offsets + np.arange(total)]


def greedy_cover(
    model: CoverageModel,
    uncovered: np.ndarray,
    slack: int,
    rng: np.random.Generator,
    robot: int,
    tolerance: float = 0.0,
    distance_scale: float | None = None,
) -> list[int]:
    """A greedy set cover, stopping as soon as at most `slack` coverable cells stay unseen.

    Each round takes a node among those whose score is within `tolerance` (a fraction) of
    the best, at random, so restarts differ. The score is the number of new cells, divided
    by (1 + d / distance_scale) when `distance_scale` is set, d being the path distance to
    the nearest node already chosen (or the robot), which favours compact covers.
    """
    u = uncovered.copy()
    remaining = int(u.sum())
    gains = (model.cover @ u.astype(np.int64)).astype(np.float64)
    chosen: list[int] = []
    near = model.dist[robot].copy() if distance_scale else None
    while remaining > slack:
        score = gains if near is None else gains / (1.0 + near / distance_scale)
        best = score.max()
        if best <= 0:
            break
        pool = np.nonzero(score >= best * (1.0 - tolerance) - _EPS)[0]
        pick = int(pool[rng.integers(len(pool))]) if len(pool) > 1 else int(pool[0])
        row = model.row(pick)
        new = row[u[row]]
        u[new] = False
        remaining -= len(new)
        gains -= np.bincount(_rows_of_columns(model, new), minlength=model.node_count)
        chosen.append(pick)
        if near is not None:
            np.minimum(near, model.dist[pick], out=near)
    return chosen


# --------------------------------------------------------------------------- TSP
def path_cost(dist: np.ndarray, order: Sequence[int]) -> float:
    order = np.asarray(order, dtype=np.int64)
    return float(dist[order[:-1], order[1:]].sum()) if len(order) > 1 else 0.0


def _two_opt_open(dist: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Best-improvement 2-opt on an open path with a fixed first node (symmetric distances)."""
    m = len(p)
    if m < 3:
        return p
    while True:
        prev = p[:-1]  # p[i-1] for i = 1..m-1
        first = p[1:]  # p[i]
        nxt = np.append(p[2:], -1)  # p[j+1] for j = 1..m-1 (-1: j is the end)
        last = p[1:]  # p[j]
        has_next = nxt >= 0
        nxt_safe = np.where(has_next, nxt, 0)
        # delta[i, j] for reversing p[i..j]
        before = dist[prev, first][:, None] + np.where(has_next, dist[last, nxt_safe], 0.0)[None, :]
        after = dist[prev[:, None], last[None, :]] + np.where(
            has_next[None, :], dist[first[:, None], nxt_safe[None, :]], 0.0
        )
        delta = after - before
        delta[np.tril_indices(m - 1)] = 0.0
        k = int(np.argmin(delta))
        if delta.flat[k] > -1e-7:
            return p
        i, j = np.unravel_index(k, delta.shape)
        i, j = int(i) + 1, int(j) + 1
        p = np.concatenate([p[:i], p[i : j + 1][::-1], p[j + 1 :]])


def _or_opt_open(dist: np.ndarray, p: np.ndarray, max_segment: int = 3) -> np.ndarray:
    """Move a segment of 1..max_segment nodes (maybe reversed) elsewhere in an open path."""
    improved = True
    base = path_cost(dist, p)
    while improved:
        improved = False
        m = len(p)
        for s in range(1, max_segment + 1):
            for i in range(1, m - s + 1):
                seg = p[i : i + s]
                rest = np.concatenate([p[:i], p[i + s :]])
                removed = path_cost(dist, rest)
                # insert after rest[k], k = 0..len(rest)-1 (k = last: append at the end)
                a = rest
                b = np.append(rest[1:], -1)
                has_b = b >= 0
                b_safe = np.where(has_b, b, 0)
                link = np.where(has_b, dist[a, b_safe], 0.0)
                inner = path_cost(dist, seg)
                fwd = dist[a, seg[0]] + np.where(has_b, dist[seg[-1], b_safe], 0.0) - link
                rev = dist[a, seg[-1]] + np.where(has_b, dist[seg[0], b_safe], 0.0) - link
                cost = removed + inner + np.minimum(fwd, rev)
                k = int(np.argmin(cost))
                if cost[k] < base - 1e-7:
                    piece = seg if fwd[k] <= rev[k] else seg[::-1]
                    p = np.concatenate([rest[: k + 1], piece, rest[k + 1 :]])
                    base = path_cost(dist, p)
                    improved = True
                    break
            if improved:
                break
    return p


def open_tsp_order(
    dist: np.ndarray, exact_max_nodes: int = EXACT_TSP_MAX_NODES, x0: Sequence[int] | None = None
) -> np.ndarray:
    """Order of an open path through all nodes of `dist` starting at node 0 (ending anywhere).

    Returning to node 0 is made free (its column set to 0), so the best cycle is the best
    open path. Exact dynamic programming up to `exact_max_nodes`, else Lin-Kernighan from a
    nearest-neighbour (or given) start, then 2-opt and or-opt on the open path.
    """
    n = len(dist)
    if n <= 2:
        return np.arange(n)
    closed = np.array(dist, dtype=np.float64)
    closed[:, 0] = 0.0
    if n <= exact_max_nodes:
        perm, _ = solve_tsp_dynamic_programming(closed)
        return np.asarray(perm, dtype=np.int64)
    if x0 is None:
        x0 = _nearest_neighbour(dist)
    perm, _ = solve_tsp_lin_kernighan(closed, x0=[int(v) for v in x0])
    p = np.asarray(perm, dtype=np.int64)
    for _ in range(4):
        before = path_cost(dist, p)
        p = _or_opt_open(dist, _two_opt_open(dist, p))
        if path_cost(dist, p) >= before - 1e-7:
            break
    return p


def _nearest_neighbour(dist: np.ndarray) -> list[int]:
    n = len(dist)
    left = np.ones(n, dtype=bool)
    left[0] = False
    order = [0]
    for _ in range(n - 1):
        d = np.where(left, dist[order[-1]], np.inf)
        nxt = int(np.argmin(d))
        order.append(nxt)
        left[nxt] = False
    return order


# --------------------------------------------------------------------------- plans
@dataclass
class CoveragePlan:
    """Viewpoints in visiting order and the node path that visits them (local indices)."""

    order: list[int]  # robot first, then the viewpoints
    path: list[int]  # node by node, robot first, cut where the episode completes
    length: float  # metres along `path` (to completion, or to its end if incomplete)
    complete: bool  # whether scanning along `path` meets the done rule
    remaining: int  # coverable cells still unseen at the end of `path`
    stats: dict = field(default_factory=dict)


def simulate_path(
    model: CoverageModel, path: Sequence[int], uncovered: np.ndarray, slack: int
) -> tuple[int, float, int]:
    """Scan at every node of `path` in order; returns (nodes needed, metres, cells left).

    `nodes needed` is the length of the shortest prefix whose scans leave at most `slack`
    coverable cells unseen (len(path) if none does; 1 if the robot's own place suffices).
    """
    u = uncovered.copy()
    remaining = int(u.sum())
    length = 0.0
    world = model.world
    for idx, node in enumerate(path):
        if idx:
            a, b = world[path[idx - 1]], world[node]
            length += float(np.hypot(b[0] - a[0], b[1] - a[1]))
        row = model.row(node)
        new = row[u[row]]
        if new.size:
            u[new] = False
            remaining -= len(new)
        if remaining <= slack:
            return idx + 1, length, remaining
    return len(path), length, remaining


def evaluate_order(model: CoverageModel, order: Sequence[int], uncovered: np.ndarray, slack: int) -> CoveragePlan:
    """Expand, simulate and cut an order (robot first) into a plan."""
    path = model.expand(order)
    needed, length, remaining = simulate_path(model, path, uncovered, slack)
    path = path[:needed]
    # Keep only the viewpoints reached before completion.
    reached, pos = [int(order[0])], 0
    for v in order[1:]:
        seg = model.path(reached[-1], int(v))
        pos += len(seg) - 1
        if pos > needed - 1:
            break
        reached.append(int(v))
    return CoveragePlan(reached, list(path), length, remaining <= slack, remaining)


def _order_viewpoints(model: CoverageModel, robot: int, viewpoints: Sequence[int], exact_max_nodes: int) -> list[int]:
    nodes = [robot] + [int(v) for v in dict.fromkeys(viewpoints) if int(v) != robot]
    sub = model.dist[np.ix_(nodes, nodes)]
    perm = open_tsp_order(sub, exact_max_nodes)
    return [nodes[int(i)] for i in perm]


def prune_plan(
    model: CoverageModel,
    plan: CoveragePlan,
    uncovered: np.ndarray,
    slack: int,
    deadline: float = np.inf,
) -> CoveragePlan:
    """Drop viewpoints the path does not need: the rest of the path still completes, no later.

    The scans along the whole path count, intermediate nodes included, so a viewpoint whose
    cells are seen on the way through others goes.
    """
    improved = True
    while improved and time.perf_counter() < deadline:
        improved = False
        # Try the viewpoints that cost the most detour first.
        order = plan.order
        if len(order) <= 1:
            break
        detour = []
        for i in range(1, len(order)):
            a = order[i - 1]
            b = order[i + 1] if i + 1 < len(order) else None
            through = model.dist[a, order[i]] + (model.dist[order[i], b] if b is not None else 0.0)
            direct = model.dist[a, b] if b is not None else 0.0
            detour.append(through - direct)
        for i in np.argsort(detour, kind="stable")[::-1]:
            i = int(i) + 1
            trial = evaluate_order(model, order[:i] + order[i + 1 :], uncovered, slack)
            if _better(trial, plan, allow_equal=True):
                plan = trial
                improved = True
                break
    return plan


def _better(a: CoveragePlan, b: CoveragePlan, allow_equal: bool = False) -> bool:
    """Complete beats incomplete; then fewer cells left (if incomplete); then shorter."""
    if a.complete != b.complete:
        return a.complete
    if not a.complete and a.remaining != b.remaining:
        return a.remaining < b.remaining
    if allow_equal:
        return a.length <= b.length + 1e-7
    return a.length < b.length - 1e-7


def refine(
    model: CoverageModel,
    robot: int,
    viewpoints: Sequence[int],
    uncovered: np.ndarray,
    slack: int,
    exact_max_nodes: int = EXACT_TSP_MAX_NODES,
    rounds: int = 3,
    deadline: float = np.inf,
    order: Sequence[int] | None = None,
) -> CoveragePlan:
    """Order the viewpoints, prune with the path's scans, re-order; repeat while it helps."""
    if order is None:
        order = _order_viewpoints(model, robot, viewpoints, exact_max_nodes)
    plan = evaluate_order(model, list(order), uncovered, slack)
    for _ in range(rounds):
        plan = prune_plan(model, plan, uncovered, slack, deadline)
        if time.perf_counter() >= deadline:
            break
        reordered = evaluate_order(
            model, _order_viewpoints(model, robot, plan.order[1:], exact_max_nodes), uncovered, slack
        )
        if not _better(reordered, plan):
            break
        plan = reordered
    return plan


def plan_coverage(
    model: CoverageModel,
    robot: int,
    uncovered: np.ndarray,
    rng: np.random.Generator,
    restarts: int = 8,
    warm_order: Sequence[int] | None = None,
    exact_max_nodes: int = EXACT_TSP_MAX_NODES,
    time_limit: float | None = None,
) -> CoveragePlan:
    """The shortest of several covers, each ordered and pruned; `warm_order` competes too.

    Restart 0 is plain greedy (ties at random); the others add a random score tolerance
    and a random distance discount, so their covers differ in count and compactness.
    """
    deadline = time.perf_counter() + time_limit if time_limit else np.inf
    slack = model.slack(uncovered)
    best: CoveragePlan | None = None
    if warm_order is not None:
        warm = [robot] + [int(v) for v in warm_order if int(v) != robot]
        best = refine(model, robot, [], uncovered, slack, exact_max_nodes, deadline=deadline, order=warm)
        if not best.complete:
            best = None
    tried = 0
    for r in range(restarts):
        if best is not None and time.perf_counter() >= deadline:
            break
        if r == 0:
            tolerance, scale = 0.0, None
        else:
            tolerance = float(rng.choice([0.0, 0.1, 0.2, 0.3]))
            scale = float(rng.choice([0.0, 10.0, 20.0, 40.0, 80.0])) or None
        viewpoints = greedy_cover(model, uncovered, slack, rng, robot, tolerance, scale)
        plan = refine(model, robot, viewpoints, uncovered, slack, exact_max_nodes, deadline=deadline)
        tried += 1
        if best is None or _better(plan, best):
            best = plan
    assert best is not None
    best.stats["restarts"] = tried
    return best


def choose_viewpoints(
    model: CoverageModel,
    robot: int | None = None,
    known_free: np.ndarray | None = None,
    seed: int = 0,
    restarts: int = 8,
) -> list[int]:
    """Lattice node ids of the viewpoints of the best plan, in visiting order.

    The robot's own scan (at the start if `robot` is None) is taken as given; coverage is
    complete when at most `done_unknown_cells` ground-truth free cells stay unseen.
    """
    robot_local = model.start if robot is None else int(model.local[robot])
    uncovered = _uncovered_after_own_scan(model, robot_local, known_free)
    plan = plan_coverage(model, robot_local, uncovered, np.random.default_rng(seed), restarts)
    return [int(model.nodes[v]) for v in plan.order[1:]]


def _uncovered_after_own_scan(model: CoverageModel, robot: int, known_free: np.ndarray | None) -> np.ndarray:
    uncovered = model.uncovered(known_free)
    uncovered[model.row(robot)] = False
    return uncovered


def coverage_plan(
    ground_truth: GroundTruthMap, protocol: Protocol, seed: int = 0, restarts: int = 8
) -> tuple[CoverageModel, CoveragePlan]:
    """The ground-truth coverage plan from the start (the start's scan already given)."""
    model = coverage_model(ground_truth, protocol)
    uncovered = _uncovered_after_own_scan(model, model.start, None)
    plan = plan_coverage(model, model.start, uncovered, np.random.default_rng(seed), restarts)
    return model, plan


def coverage_tour(
    ground_truth: GroundTruthMap, protocol: Protocol, seed: int = 0, restarts: int = 8
) -> list[tuple[float, float]]:
    """The `Optimal` tour: lattice waypoints in metres, node by node, the start (0, 0) first.

    Consecutive waypoints are joined by ground-truth graph edges; the tour ends where the
    episode completes.
    """
    model, plan = coverage_plan(ground_truth, protocol, seed, restarts)
    return [tuple(map(float, model.world[v])) for v in plan.path]


# --------------------------------------------------------------------------- oracle runs
class OracleEpisode(Episode):
    """An episode whose moves need ground-truth free segments only (the `Optimal` rule)."""

    def move(self, waypoint: Sequence[float]) -> None:
        cell = self.waypoint_cell(waypoint)
        if not segment_is_known_free(self.map.free, self.cell, cell):
            raise MotionError(
                f"segment ({self.position[0]:.3f}, {self.position[1]:.3f}) -> "
                f"({float(waypoint[0]):.3f}, {float(waypoint[1]):.3f}) crosses ground-truth occupied cells"
            )
        d = self.protocol.node_resolution
        target = (round(float(waypoint[0]) / d) * d, round(float(waypoint[1]) / d) * d)
        self.distance += float(np.hypot(target[0] - self.position[0], target[1] - self.position[1]))
        self.position = target
        self.cell = cell
        self.trajectory.append(target)
        self._sense()


def run_oracle_episode(
    ground_truth: GroundTruthMap,
    planner: "Planner",
    protocol: Protocol,
    seed: int = 0,
    on_step: Callable[[Episode], None] | None = None,
) -> EpisodeResult:
    """`run_episode` with the oracle's motion rule: segments free in the ground truth.

    Lattice and in-grid checks are the simulator's; only the known-free test is replaced.
    """
    episode = OracleEpisode(ground_truth, protocol)
    planner.reset(ground_truth, protocol, seed)
    decision_ms: list[float] = []
    failure = ""
    violations = 0
    if on_step is not None:
        on_step(episode)
    while not episode.complete and episode.steps < protocol.max_steps:
        observation = episode.observe()
        t0 = time.perf_counter()
        waypoints = planner.plan(observation)
        decision_ms.append((time.perf_counter() - t0) * 1e3)
        if not waypoints:
            failure = "no reachable target left"
            break
        try:
            for waypoint in waypoints:
                episode.move(waypoint)
                if on_step is not None:
                    on_step(episode)
                if episode.complete or episode.steps >= protocol.max_steps:
                    break
        except MotionError as error:
            failure = f"motion rule: {error}"
            violations += 1
            break
    if not episode.complete and not failure:
        failure = f"step limit ({protocol.max_steps}) reached"
    complete = episode.complete
    return EpisodeResult(
        map_name=ground_truth.name,
        planner=getattr(planner, "name", type(planner).__name__),
        trajectory=list(episode.trajectory),
        distance_m=episode.completion_distance if complete else episode.distance,
        steps=(episode.complete_after_waypoint - 1) if complete else episode.steps,
        complete=complete,
        explored_ratio=episode.explored_ratio,
        decision_ms=decision_ms,
        seed=seed,
        failure="" if complete else failure,
        motion_violations=violations,
        complete_after_waypoint=episode.complete_after_waypoint,
    )


def replay_oracle(
    ground_truth: GroundTruthMap, waypoints: Sequence[Sequence[float]], protocol: Protocol
) -> EpisodeResult:
    """Replay a tour (first row the start) under the oracle rule; distance at completion."""

    class _Fixed:
        name = "replay"

        def reset(self, *args) -> None:
            self.done = False

        def plan(self, observation) -> list:
            if self.done:
                return []
            self.done = True
            return [tuple(map(float, p)) for p in waypoints[1:]]

    return run_oracle_episode(ground_truth, _Fixed(), protocol)  # type: ignore[arg-type]
