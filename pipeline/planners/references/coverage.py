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

import hashlib
import time
from collections import OrderedDict
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from pipeline.lattice.graph import LatticeGraph, LatticeSpec
from pipeline.lattice.tsp import EXACT_TSP_MAX_NODES, open_tsp_order
from pipeline.world.maps import GroundTruthMap
from pipeline.world.planner import Observation, Planner
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, OCCUPIED, scan
from pipeline.world.simulator import Episode, EpisodeResult, replay, run_episode

HOP_BONUS_M = 1e-6  # shortest-path tie-break towards more lattice nodes (more scans)
PATH_JITTER_M = 1e-9  # below the hop bonus even summed over a path of hundreds of edges
DEFAULT_RESTARTS = 8
DEFAULT_LNS_ITERATIONS = 30
RESTART_METHODS = ("greedy", "insertion")
_EPS = 1e-9


# --------------------------------------------------------------------------- the model
def lattice_spec(ground_truth: GroundTruthMap, protocol: Protocol) -> LatticeSpec:
    """The lattice every planner uses on this map (as `GraphPlanner.reset` builds it)."""
    return LatticeSpec.for_map(ground_truth, protocol)


def ground_truth_graph(ground_truth: GroundTruthMap, protocol: Protocol) -> LatticeGraph:
    """The lattice graph of a belief that equals the ground truth: edges = free segments."""
    graph = LatticeGraph(lattice_spec(ground_truth, protocol))
    belief = np.where(ground_truth.free, FREE, OCCUPIED).astype(np.uint8)
    graph.update(belief, None)
    return graph


def node_cell_matrix(
    ground_truth: GroundTruthMap, graph: LatticeGraph, nodes: np.ndarray, protocol: Protocol
) -> csr_matrix:
    """Boolean nodes x cells (flat grid index) matrix: row k = free cells a scan at `nodes[k]` reveals."""
    rows, cols = [], []
    for k, node in enumerate(nodes):
        cell = (int(graph.node_cells[node][0]), int(graph.node_cells[node][1]))
        cells = scan(ground_truth.free, cell, protocol.sensor_range_cells).free
        rows.append(np.full(cells.size, k, dtype=np.int64))
        cols.append(cells.astype(np.int64))
    r = np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)
    c = np.concatenate(cols) if cols else np.zeros(0, dtype=np.int64)
    return csr_matrix((np.ones(r.size, dtype=bool), (r, c)), shape=(len(nodes), ground_truth.free.size))


def reachable_nodes(graph: LatticeGraph) -> tuple[int, np.ndarray]:
    """(the start's lattice node, every node reachable from it on `graph`): where a robot can ever sense."""
    start = graph.nearest_node((0.0, 0.0))
    return start, np.nonzero(np.isfinite(graph.shortest_paths(start)[0]))[0]


def unobservable_free_cells(ground_truth: GroundTruthMap, protocol: Protocol) -> int:
    """Free cells that no scan from a lattice node reachable from the start reveals.

    No planner ever sees them: a robot senses only at lattice nodes, and only at those the
    ground truth lets it reach. More of them than `done_unknown_cells` and no episode on the
    map can complete (clutter specks and ragged walls in a fine SLAM map hide a few hundred).
    """
    graph = ground_truth_graph(ground_truth, protocol)
    _, nodes = reachable_nodes(graph)
    seen = np.unique(node_cell_matrix(ground_truth, graph, nodes, protocol).indices).size
    return ground_truth.free_cell_count - seen


class CoverageModel:
    """Ground-truth lattice graph, per-node scans and all-pairs shortest paths of one map.

    Nodes are renumbered locally: local index k is lattice node `nodes[k]`, one of the nodes
    reachable from the start on the ground-truth graph. Cells are renumbered too: column j
    is flat grid cell `cells[j]`, one of the free cells that some reachable node's scan
    reveals (the others can never be seen and only count against the done rule).
    """

    def __init__(self, ground_truth: GroundTruthMap, protocol: Protocol):
        self.ground_truth = ground_truth
        self.protocol = protocol
        self.graph = graph = ground_truth_graph(ground_truth, protocol)
        self.start_node, self.nodes = reachable_nodes(graph)
        self.local = np.full(graph.node_count, -1, dtype=np.int64)
        self.local[self.nodes] = np.arange(len(self.nodes))
        self.start = int(self.local[self.start_node])
        adjacency = graph.adjacency()[self.nodes][:, self.nodes].tocsr()
        # Among equally long paths prefer the one through more lattice nodes (two 4 m hops
        # rather than one 8 m edge): the robot scans at every node, so more scans for free.
        # A tinier fixed jitter per edge then makes shortest paths unique, so that the rest
        # of a shortest path is the shortest path from any node on it: a robot replanning
        # halfway keeps to the path it was on.
        jitter = np.random.default_rng(0).random(adjacency.data.size) * PATH_JITTER_M
        adjacency.data = adjacency.data - HOP_BONUS_M + jitter
        self.dist, pred = dijkstra(adjacency, directed=False, return_predecessors=True)
        self.pred = pred.astype(np.int64)
        full = node_cell_matrix(ground_truth, graph, self.nodes, protocol)
        self.cells = np.unique(full.indices)
        self.column = np.full(ground_truth.free.size, -1, dtype=np.int64)
        self.column[self.cells] = np.arange(len(self.cells))
        self.cover = full[:, self.cells].tocsr()  # nodes x coverable cells
        self.cover.sort_indices()
        # Each node's scan as a bitset over the coverable cells (64 cells per word): the
        # objectives select words from it instead of re-packing a dense boolean matrix.
        self.cover_bits = pack_bits(self.cover.toarray())
        self.free_cell_count = ground_truth.free_cell_count
        self.world = graph.node_world[self.nodes].astype(np.float64)
        self.node_cells = graph.node_cells[self.nodes]
        self._paths: dict[tuple[int, int], tuple[int, ...]] = {}

    @property
    def node_count(self) -> int:
        return len(self.nodes)

    def row(self, k: int) -> np.ndarray:
        """Columns (coverable cells) revealed by a scan at local node k."""
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

    def path_length(self, path: Sequence[int]) -> float:
        """Metres along a node path (straight segments between consecutive nodes)."""
        if len(path) < 2:
            return 0.0
        steps = np.diff(self.world[np.asarray(path)], axis=0)
        return float(np.hypot(steps[:, 0], steps[:, 1]).sum())

    def uncovered(self, known_free: np.ndarray | None = None) -> np.ndarray:
        """Mask over columns: coverable cells not known free yet (all of them if None)."""
        if known_free is None:
            return np.ones(len(self.cells), dtype=bool)
        return ~known_free.reshape(-1)[self.cells]

    def slack(self) -> int:
        """How many coverable cells may stay unseen when the episode is complete.

        The done rule counts every ground-truth free cell; the ones no reachable scan
        reveals are lost anyway. If they alone exceed the allowance, all coverable cells
        are needed (and the episode cannot complete).
        """
        uncoverable = self.free_cell_count - len(self.cells)
        return max(0, self.protocol.done_unknown_cells - uncoverable)


_MODEL_CACHE: "OrderedDict[tuple, CoverageModel]" = OrderedDict()
_MODEL_CACHE_SIZE = 4


def coverage_model(ground_truth: GroundTruthMap, protocol: Protocol) -> CoverageModel:
    """The `CoverageModel` of a map, cached (the last few maps) so planners share it."""
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


def pack_bits(rows: np.ndarray) -> np.ndarray:
    """Boolean rows (n, m) as uint64 bitsets (n, ceil(m / 64)), bit j of a row in word j // 64."""
    packed = np.packbits(rows, axis=1, bitorder="little")
    packed = np.pad(packed, ((0, 0), (0, (-packed.shape[1]) % 8)))
    return np.ascontiguousarray(packed).view(np.uint64)


class CoverageObjective:
    """The cells a plan must still see, with each node's scan packed as a bitset over them.

    Simulating a path is then a cumulative OR of its nodes' bitsets and a popcount.
    """

    def __init__(self, model: CoverageModel, uncovered: np.ndarray):
        self.model = model
        self.uncovered = uncovered
        self.total = int(np.count_nonzero(uncovered))
        self.slack = model.slack()
        # Whether the done rule can be met at all (the never-seen cells alone may exceed it).
        self.achievable = model.free_cell_count - len(model.cells) <= model.protocol.done_unknown_cells
        # The model's scan bitsets masked to the uncovered cells, keeping only the words that
        # hold some (at least one word, so that empty objectives keep their shapes). Only
        # counts of set bits are ever read, so which bit a cell has does not matter.
        mask = pack_bits(np.asarray(uncovered, dtype=bool)[None, :])[0]
        words = np.nonzero(mask)[0] if mask.any() else np.zeros(1, dtype=np.int64)
        self.bits = np.ascontiguousarray(model.cover_bits[:, words] & mask[words])
        self.gain = np.bitwise_count(self.bits).sum(axis=1).astype(np.int64)

    @property
    def need(self) -> int:
        """Cells still to see before the episode is complete (<= 0: complete already)."""
        return self.total - self.slack

    def simulate(self, path: Sequence[int]) -> tuple[int, float, int]:
        """Scan at every node of `path` in order: (nodes needed, metres, cells left unseen).

        `nodes needed` is the length of the shortest prefix after which at most `slack`
        cells are unseen (the whole path if none).
        """
        p = np.asarray(path, dtype=np.int64)
        seen = np.bitwise_or.accumulate(self.bits[p], axis=0)
        remaining = self.total - np.bitwise_count(seen).sum(axis=1).astype(np.int64)
        done = remaining <= self.slack
        needed = int(np.argmax(done)) + 1 if done.any() else len(p)
        return needed, self.model.path_length(p[:needed]), int(remaining[needed - 1])

    def seen_by(self, path: Sequence[int]) -> np.ndarray:
        """Bitset of the cells seen by scanning along `path`."""
        return np.bitwise_or.reduce(self.bits[np.asarray(path, dtype=np.int64)], axis=0)

    def gains_after(self, seen: np.ndarray) -> np.ndarray:
        """Per node: cells its scan would add to `seen`."""
        return np.bitwise_count(self.bits & ~seen).sum(axis=1).astype(np.int64)


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


def _detours(dist: np.ndarray, order: Sequence[int]) -> np.ndarray:
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
        for i in np.argsort(_detours(objective.model.dist, order), kind="stable")[::-1]:
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
            plan = _refine_rounds(objective, evaluate_order(objective, topped), exact_max_nodes, rounds, deadline,
                                  relocate_radius_m)
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
        best = refine(objective, warm, exact_max_nodes, deadline=deadline,
                      relocate_radius_m=relocate_radius_m, reorder_first=False)
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
        model, model.start, uncovered, np.random.default_rng(seed), restarts,
        lns_iterations=lns_iterations, time_limit=time_limit,
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
    return [tuple(map(float, model.world[v])) for v in plan.path]


# --------------------------------------------------------------------------- oracle runs
class _OracleRule:
    """Wraps a planner so that the simulator applies the oracle motion rule to its moves."""

    ignores_motion_rule = True

    def __init__(self, planner: Planner):
        self.planner = planner
        self.name = getattr(planner, "name", "") or type(planner).__name__

    def reset(self, ground_truth: GroundTruthMap, protocol: Protocol, seed: int) -> None:
        self.planner.reset(ground_truth, protocol, seed)

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
