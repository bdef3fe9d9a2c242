"""Region-evaluated global graph (paper Sec. IV-B.2-3): known nodes plus credible predictions.

Each step: score the boundary and unobserved regions by r(g) = w_f/d_f + w_r/d_r; keep
predicted nodes in high-score regions; replace dense predictions in low-score unobserved
regions by one centroid node (the predicted node nearest the region's centre); drop the
rest. Utilities of known nodes are boosted by
the predicted nodes in range (bounded by what the sensor could see), and predicted nodes
are linked to neighbours through space that is not known to be occupied.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import dijkstra
from scipy.spatial import cKDTree

from pipeline.lattice.graph import NODE_UNKNOWN, REGION_BOUNDARY, REGION_UNOBSERVED, LatticeGraph
from pipeline.world.geometry import walk_cells
from pipeline.world.sensor import OCCUPIED

KNOWN, PREDICTED, CENTROID = 0, 1, 2
FEATURE_NAMES = ("dx", "dy", "utility", "guidepost", "visited", "is_predicted", "is_centroid")


@dataclass(frozen=True)
class RegionEvaluationConfig:
    """Region score weights and the filters of Sec. IV-B.2 (tuned on training mazes only)."""

    frontier_weight: float = 1.0  # w_f
    robot_weight: float = 1.0  # w_r
    nearest_frontiers: int = 10  # Z
    keep_share: float = 0.5  # share of scored regions (best first) that keep their predictions
    centroid_density: float = 0.25  # predicted / lattice nodes in a low-score unobserved region to add its centroid


def region_scores(
    labels: np.ndarray,
    centroids: np.ndarray,
    frontier_xy: np.ndarray,
    robot_xy: np.ndarray,
    config: RegionEvaluationConfig,
) -> np.ndarray:
    """r(g) for boundary and unobserved regions (NaN for explored ones)."""
    scored = (labels == REGION_BOUNDARY) | (labels == REGION_UNOBSERVED)
    flat_centroids = centroids.reshape(-1, 2)
    scores = np.full(len(flat_centroids), np.nan)
    idx = np.nonzero(scored.reshape(-1))[0]
    if idx.size == 0:
        return scores.reshape(labels.shape)
    c = flat_centroids[idx]
    d_r = np.maximum(np.hypot(*(c - robot_xy).T), 1e-6)
    score = config.robot_weight / d_r
    if len(frontier_xy):
        d = np.hypot(c[:, None, 0] - frontier_xy[None, :, 0], c[:, None, 1] - frontier_xy[None, :, 1])
        z = min(config.nearest_frontiers, d.shape[1])
        d_f = np.maximum(np.partition(d, z - 1, axis=1)[:, :z].mean(axis=1), 1e-6)
        score = score + config.frontier_weight / d_f
    scores[idx] = score
    return scores.reshape(labels.shape)


@dataclass(frozen=True)
class RegionSelection:
    """One step's region evaluation, before any predictions are filtered by it."""

    labels: np.ndarray  # region labels (explored / boundary / unobserved)
    centroids: np.ndarray  # region centres, world (x, y)
    scores: np.ndarray  # r(g), NaN for explored regions
    keep_region: np.ndarray  # regions whose predictions are kept
    node_region: np.ndarray  # (row, col) region of every lattice node
    lattice_per_region: np.ndarray  # lattice nodes per region


def select_regions(graph: LatticeGraph, robot_xy: np.ndarray, config: RegionEvaluationConfig) -> RegionSelection:
    """Score the regions and pick those that keep their predictions (the best `keep_share`)."""
    labels = graph.region_labels()
    centroids = graph.region_centroids()
    frontier_cells = np.argwhere(graph.frontier)[:, ::-1]
    frontier_xy = graph.spec.cell_to_world(frontier_cells) if len(frontier_cells) else np.zeros((0, 2))
    scores = region_scores(labels, centroids, frontier_xy, np.asarray(robot_xy, dtype=np.float64), config)
    finite = np.isfinite(scores)
    keep_region = np.zeros(labels.shape, dtype=bool)
    if finite.any():
        ranked = np.sort(scores[finite])[::-1]
        count = int(np.ceil(config.keep_share * ranked.size))
        cutoff = ranked[count - 1] if count > 0 else np.inf
        keep_region = finite & (scores >= cutoff)
    return RegionSelection(labels, centroids, scores, keep_region, graph.node_region, graph.nodes_per_region)


def filter_predictions(
    graph: LatticeGraph, predicted: np.ndarray, selection: RegionSelection, config: RegionEvaluationConfig
) -> tuple[np.ndarray, np.ndarray]:
    """V_u from V_p under a region selection: (kept predicted node ids, centroid node positions (K, 2))."""
    predicted = np.asarray(predicted, dtype=np.int64)
    pr = selection.node_region[predicted]
    kept = predicted[selection.keep_region[pr[:, 0], pr[:, 1]]] if predicted.size else predicted
    # Low-score unobserved regions: a centroid when predictions there are dense enough.
    finite = np.isfinite(selection.scores)
    low_unobserved = finite & ~selection.keep_region & (selection.labels == REGION_UNOBSERVED)
    predicted_per_region = np.zeros(selection.labels.shape, dtype=np.int64)
    if predicted.size:
        np.add.at(predicted_per_region, (pr[:, 0], pr[:, 1]), 1)
    density = predicted_per_region / np.maximum(selection.lattice_per_region, 1)
    centroid_regions = low_unobserved & (density >= config.centroid_density) & (predicted_per_region > 0)
    return kept, region_representatives(graph, predicted, pr, centroid_regions, selection.centroids)


def region_representatives(
    graph: LatticeGraph, predicted: np.ndarray, predicted_region: np.ndarray, regions: np.ndarray, centroids: np.ndarray
) -> np.ndarray:
    """World (x, y) of one centroid node per marked region: its predicted node nearest the region's centre.

    The paper adds the region centroid v_g itself; the centre of a 20 m maze region is more
    often than not outside free space, which makes the node false (Table I counts it) and
    leaves the policy a node it cannot reach. The predicted node nearest the centre stands for the region as compactly
    and is free as often as any kept prediction. Rows follow the regions' row-major order.
    """
    if not regions.any() or predicted.size == 0:
        return np.zeros((0, 2))
    in_marked = regions[predicted_region[:, 0], predicted_region[:, 1]]
    ids, cells = predicted[in_marked], predicted_region[in_marked]
    flat = cells[:, 0] * regions.shape[1] + cells[:, 1]
    xy = graph.node_world[ids]
    distance = np.hypot(*(xy - centroids[cells[:, 0], cells[:, 1]]).T)
    order = np.lexsort((distance, flat))  # by region, nearest first
    first = order[np.r_[True, flat[order][1:] != flat[order][:-1]]]
    return xy[first].astype(np.float64)


@dataclass(frozen=True)
class GlobalGraphConfig:
    region: RegionEvaluationConfig = RegionEvaluationConfig()
    centroid_link_nodes: float = 7.5  # node spacings (30 m at d_n = 4 m): centroids link to nodes this close ...
    centroid_links: int = 4  # ... at most this many
    position_scale_nodes: float = 10.0  # node spacings (40 m at d_n = 4 m): dx, dy features are divided by this
    utility_scale: float = 100.0  # utility feature = min(u / utility_scale, 1)
    max_nodes: int = 512  # features() pads or trims to this many nodes
    guidepost_min_utility: float = 2.0  # the guidepost leads to the nearest unvisited node with this utility, as
    # the planners' useful_nodes (min_utility 2): with "utility > 0" the robot's own node won most steps
    use_region_evaluation: bool = True  # False: keep every prediction (the paper's ablation)


class GlobalGraph:
    """Nodes (known / predicted / centroid), utilities, edges and policy features for one step."""

    def __init__(self, lattice: LatticeGraph, config: GlobalGraphConfig = GlobalGraphConfig()):
        self.lattice = lattice
        self.config = config
        self.positions = np.zeros((0, 2))
        self.types = np.zeros(0, dtype=np.int8)
        self.lattice_ids = np.zeros(0, dtype=np.int64)
        self.utility = np.zeros(0)
        self.visited = np.zeros(0, dtype=bool)
        self.adjacency = coo_matrix((0, 0)).tocsr()
        self.region_scores = np.zeros((0, 0))

    @property
    def node_count(self) -> int:
        return len(self.positions)

    def update(
        self,
        belief: np.ndarray,
        robot_xy,
        predicted: np.ndarray | None,
        visited_lattice: np.ndarray | None = None,
        counted: np.ndarray | None = None,
    ) -> None:
        """Rebuild the step's global graph; the lattice part must already be up to date.

        `counted` (default: `predicted`) are the predicted nodes the utility boost counts.
        """
        lattice = self.lattice
        robot_xy = np.asarray(robot_xy, dtype=np.float64)
        known = lattice.free_nodes
        predicted = np.zeros(0, dtype=np.int64) if predicted is None else np.asarray(predicted, dtype=np.int64)
        selection = None
        if self.config.use_region_evaluation:
            selection = select_regions(lattice, robot_xy, self.config.region)
            kept, centroid_xy = filter_predictions(lattice, predicted, selection, self.config.region)
            self.region_scores = selection.scores
        else:
            kept, centroid_xy = predicted, np.zeros((0, 2))
        self.region_selection: RegionSelection | None = selection  # None without region evaluation
        self.lattice_ids = np.concatenate([known, kept, np.full(len(centroid_xy), -1)])
        self.types = np.concatenate(
            [np.full(len(known), KNOWN), np.full(len(kept), PREDICTED), np.full(len(centroid_xy), CENTROID)]
        ).astype(np.int8)
        self.positions = np.concatenate([lattice.node_world[known], lattice.node_world[kept], centroid_xy]).astype(
            np.float64
        )
        self.visited = np.zeros(self.node_count, dtype=bool)
        if visited_lattice is not None and len(known):
            self.visited[: len(known)] = visited_lattice[known]
        self.utility = np.zeros(self.node_count)
        if counted is None or counted is predicted:
            kept_c, centroid_c = kept, centroid_xy
        elif selection is not None:  # the same regions filter the counted nodes
            kept_c, centroid_c = filter_predictions(lattice, counted, selection, self.config.region)
        else:
            kept_c, centroid_c = np.asarray(counted, dtype=np.int64), np.zeros((0, 2))
        self.utility[: len(known)] = self._boosted_utility(known, kept_c, centroid_c)
        self.adjacency = self._edges(belief, known, kept, centroid_xy)

    # ------------------------------------------------------------------ utility
    def _boosted_utility(self, known: np.ndarray, kept: np.ndarray, centroid_xy: np.ndarray) -> np.ndarray:
        """u(v) = min{F_m, F (1 + N_u / N_um)} for known nodes with frontier utility F > 0."""
        lattice = self.lattice
        frontier_count = lattice.utility[known].astype(np.float64)
        utility = frontier_count.copy()
        active = np.nonzero(frontier_count > 0)[0]
        if active.size == 0:
            return utility
        r = lattice.spec.utility_range
        bound = 2.0 * np.pi * r / lattice.spec.cell_size  # F_m: cells along the range's boundary
        xy = lattice.node_world[known[active]]
        unknown_xy = lattice.node_world[lattice.node_state == NODE_UNKNOWN]
        v_u = np.concatenate([lattice.node_world[kept], centroid_xy])

        def within(points: np.ndarray) -> np.ndarray:
            """Per active node, the `points` within the utility range (a k-d tree: a building's
            thousands of nodes would make the pairwise distances the decision's largest cost)."""
            if len(points) == 0:
                return np.zeros(len(xy))
            return cKDTree(points).query_ball_point(xy, r, return_length=True).astype(np.float64)

        n_u = within(v_u)
        n_um = within(unknown_xy)
        boost = np.where(n_um > 0, 1.0 + np.minimum(n_u, n_um) / np.maximum(n_um, 1), 1.0)
        utility[active] = np.minimum(bound, frontier_count[active] * boost)
        return utility

    # ------------------------------------------------------------------ edges
    def _edges(self, belief: np.ndarray, known: np.ndarray, kept: np.ndarray, centroid_xy: np.ndarray):
        lattice = self.lattice
        index_of = np.full(lattice.node_count, -1, dtype=np.int64)
        index_of[known] = np.arange(len(known))
        index_of[kept] = len(known) + np.arange(len(kept))
        rows, cols, weights = [], [], []
        # Known-known: the lattice graph's known-free edges.
        e = lattice.edges
        w = lattice.edge_cost[lattice.edge_valid]
        rows.append(index_of[e[:, 0]])
        cols.append(index_of[e[:, 1]])
        weights.append(w)
        # Predicted to known or predicted lattice neighbours: the segment may cross unknown cells, not occupied ones.
        if len(kept):
            members = np.zeros(lattice.node_count, dtype=bool)
            members[known] = True
            members[kept] = True
            is_predicted = np.zeros(lattice.node_count, dtype=bool)
            is_predicted[kept] = True
            occupied = belief.reshape(-1) == OCCUPIED
            pairs, lengths = lattice.edges_not_crossing(occupied, members, is_predicted)
            rows.append(index_of[pairs[:, 0]])
            cols.append(index_of[pairs[:, 1]])
            weights.append(lengths)
        # Centroids to their nearest nodes in range (straight segments that cross no occupied cell).
        offset = len(known) + len(kept)
        if len(centroid_xy):
            all_xy = np.concatenate([lattice.node_world[known], lattice.node_world[kept], centroid_xy])
            cells_all = lattice.spec.world_to_cell(all_xy)
            link_range = self.config.centroid_link_nodes * lattice.spec.node_resolution
            for index, xy in enumerate(centroid_xy):
                d = np.hypot(*(all_xy - xy).T)
                d[offset + index] = np.inf
                links = 0
                for j in np.argsort(d):
                    if d[j] > link_range or links >= self.config.centroid_links:
                        break
                    if self._segment_clear(belief, cells_all[offset + index], cells_all[j]):
                        rows.append(np.array([offset + index]))
                        cols.append(np.array([j]))
                        weights.append(np.array([d[j]]))
                        links += 1
        r = np.concatenate(rows) if rows else np.zeros(0, dtype=np.int64)
        c = np.concatenate(cols) if cols else np.zeros(0, dtype=np.int64)
        w = np.concatenate(weights) if weights else np.zeros(0)
        n = self.node_count
        return coo_matrix((np.maximum(w, 1e-6), (r, c)), shape=(n, n)).tocsr()

    @staticmethod
    def _segment_clear(belief: np.ndarray, a: np.ndarray, b: np.ndarray) -> bool:
        rows, cols = belief.shape
        cells = walk_cells((int(a[0]), int(a[1])), (int(b[0]), int(b[1])))
        xs, ys = cells[:, 0], cells[:, 1]
        inside = (xs >= 0) & (xs < cols) & (ys >= 0) & (ys < rows)
        return bool(inside.all() and (belief[ys, xs] != OCCUPIED).all())

    # ------------------------------------------------------------------ queries
    def nearest(self, xy) -> int:
        return int(np.argmin(np.hypot(*(self.positions - np.asarray(xy)).T)))

    def shortest_paths(self, source: int) -> tuple[np.ndarray, np.ndarray]:
        return dijkstra(self.adjacency, directed=False, indices=source, return_predecessors=True)

    def row_order(self, robot_xy) -> np.ndarray:
        """Node indices in the order of the policy's rows: nearest to the robot first, at most max_nodes."""
        distance = np.hypot(*(self.positions - np.asarray(robot_xy, dtype=np.float64)).T)
        return np.argsort(distance, kind="stable")[: self.config.max_nodes]

    def features(self, robot_xy) -> tuple[np.ndarray, np.ndarray, int]:
        """Policy input: (max_nodes, len(FEATURE_NAMES)) features, a validity mask, the robot's row.

        Nodes beyond `max_nodes` are dropped farthest-first from the robot.
        """
        robot_xy = np.asarray(robot_xy, dtype=np.float64)
        n_max = self.config.max_nodes
        robot = self.nearest(robot_xy)
        dist, pred = self.shortest_paths(robot)
        guidepost = np.zeros(self.node_count, dtype=bool)
        reachable_unvisited = np.isfinite(dist) & ~self.visited
        useful = np.nonzero(reachable_unvisited & (self.utility >= self.config.guidepost_min_utility))[0]
        if useful.size == 0:
            useful = np.nonzero(reachable_unvisited & (self.utility > 0))[0]
        if useful.size:
            node = int(useful[np.argmin(dist[useful])])
            while node >= 0:
                guidepost[node] = True
                node = int(pred[node])
        order = self.row_order(robot_xy)
        feats = np.zeros((n_max, len(FEATURE_NAMES)), dtype=np.float32)
        mask = np.zeros(n_max, dtype=bool)
        k = len(order)
        rel = (self.positions[order] - robot_xy) / (
            self.config.position_scale_nodes * self.lattice.spec.node_resolution
        )
        feats[:k, 0:2] = rel
        feats[:k, 2] = np.minimum(self.utility[order] / self.config.utility_scale, 1.0)
        feats[:k, 3] = guidepost[order]
        feats[:k, 4] = self.visited[order]
        feats[:k, 5] = self.types[order] == PREDICTED
        feats[:k, 6] = self.types[order] == CENTROID
        mask[:k] = True
        robot_row = int(np.nonzero(order == robot)[0][0])
        return feats, mask, robot_row
