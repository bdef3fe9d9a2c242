"""The ground-truth coverage model the `Optimal` reference and DARE's expert plan on.

The ground-truth lattice graph is a `LatticeGraph` updated with a belief equal to the whole
ground truth, so its edges are exactly the segments the motion rule would allow if everything
were known. Each free lattice node reachable from the start gets the set of ground-truth free
cells its scan reveals (the protocol sensor itself, `pipeline.world.sensor.scan`), stored as a
sparse boolean matrix nodes x cells; `CoverageObjective` judges a path by those scans against
the done rule. Everything here looks at the ground truth.
"""

from __future__ import annotations

import hashlib
from collections import OrderedDict
from typing import Sequence

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

from pipeline.lattice.graph import LatticeGraph
from pipeline.lattice.spec import LatticeSpec
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, OCCUPIED, scan

HOP_BONUS_M = 1e-6  # shortest-path tie-break towards more lattice nodes (more scans)
PATH_JITTER_M = 1e-9  # below the hop bonus even summed over a path of hundreds of edges


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

    def path_length(self, path: Sequence[int] | np.ndarray) -> float:
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
