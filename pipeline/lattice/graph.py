"""Environmental Extraction (paper Sec. IV-A): the lattice graph of known nodes and the regions.

The lattice is fixed by the start cell and d_n, so every candidate edge (a node and one
of its 5x5-window neighbours) and the cells its segment crosses are known up front.
An update after a scan only re-tests edges, node states, frontiers, utilities and regions
near the cells that changed; nothing is rebuilt from scratch.
"""

from __future__ import annotations

import copy
import typing

import cv2
import numba
import numpy as np
from scipy.sparse import coo_matrix, csr_matrix
from scipy.sparse.csgraph import dijkstra

from pipeline.lattice.doors import MAX_DETOUR, door_edges_kernel
from pipeline.lattice.frontier import frontier_mask, update_frontier_window
from pipeline.lattice.spec import LatticeSpec
from pipeline.lattice.visibility import visible_counts
from pipeline.world.geometry import walk_offsets
from pipeline.world.reachability import clearance_cells
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN

NODE_UNKNOWN, NODE_FREE, NODE_OCCUPIED = 0, 1, 2
REGION_UNOBSERVED, REGION_EXPLORED, REGION_BOUNDARY = 0, 1, 2
WINDOW_RADIUS = 2  # neighbours in the 5x5 lattice window


def node_states_in(belief: np.ndarray, node_flat: np.ndarray) -> np.ndarray:
    """NODE_FREE / NODE_OCCUPIED / NODE_UNKNOWN of the nodes at flat cells `node_flat`."""
    values = belief.reshape(-1)[node_flat]
    states = np.full(len(node_flat), NODE_UNKNOWN, dtype=np.int8)
    states[values == FREE] = NODE_FREE
    states[values == OCCUPIED] = NODE_OCCUPIED
    return states


class LatticeGraph:
    """Known free nodes V_f, obstacle nodes V_o, known-free edges, utilities and regions."""

    def __init__(self, spec: LatticeSpec):
        self.spec = spec
        rows, cols = spec.shape
        ii = spec.lattice_range(0)
        jj = spec.lattice_range(1)
        self.lattice_i, self.lattice_j = ii, jj
        self.node_ij = spec.node_indices()
        self.node_world = self.node_ij * spec.node_resolution
        self.node_cells = spec.world_to_cell(self.node_world)
        self.node_flat = self.node_cells[:, 1] * cols + self.node_cells[:, 0]
        self.node_count = len(self.node_ij)
        self._id_grid = np.arange(self.node_count).reshape(len(jj), len(ii))
        self.node_state = np.full(self.node_count, NODE_UNKNOWN, dtype=np.int8)
        self.utility = np.zeros(self.node_count, dtype=np.int64)
        self.frontier = np.zeros(spec.shape, dtype=bool)
        # Region labels feed the global graph only: a lookahead's rollout copies turn them off.
        self.track_regions = True
        # Rollout copies may also leave a node's utility as a bound, the frontier cells in its range's
        # square, until a ranking needs it exactly (`stale` marks those; `exact_utilities` counts them).
        self.lazy_utilities = False
        self.stale = np.zeros(self.node_count, dtype=bool)
        self.utility_version = 0  # counts changes of `utility`, for rankings kept between them
        self._known_free: np.ndarray | None = None  # belief == FREE, made once per update when asked
        self.belief = np.full(spec.shape, UNKNOWN, dtype=np.uint8)
        self._build_candidate_edges()
        self.edge_valid = np.zeros(len(self.edge_nodes), dtype=bool)
        # An edge valid through a door node: the node's flat cell (-1: straight or invalid) and the
        # length of the way through it in metres.
        self.edge_via = np.full(len(self.edge_nodes), -1, dtype=np.int64)
        self.via_length = np.zeros(len(self.edge_nodes))
        self._edge_cost: np.ndarray | None = None
        self._adjacency = None
        self._search_matrix = None
        self._neighbour_lists: tuple[np.ndarray, np.ndarray] | None = None
        self.utility_range_cells = spec.utility_range / spec.cell_size
        region_cells = spec.region_size / spec.cell_size
        self._region_cells = region_cells
        self._region_origin = np.array(spec.start_cell, dtype=np.float64)
        rx = np.floor((np.arange(cols) - self._region_origin[0]) / region_cells).astype(np.int64)
        ry = np.floor((np.arange(rows) - self._region_origin[1]) / region_cells).astype(np.int64)
        self.region_col_of_x = rx - rx.min()
        self.region_row_of_y = ry - ry.min()
        self._region_offset = np.array([rx.min(), ry.min()])
        self.region_shape = (int(self.region_row_of_y.max()) + 1, int(self.region_col_of_x.max()) + 1)
        self.node_region = self.region_of_cells(self.node_cells)  # (row, col) of each node's region, fixed
        self.nodes_per_region = np.zeros(self.region_shape, dtype=np.int64)
        np.add.at(self.nodes_per_region, (self.node_region[:, 0], self.node_region[:, 1]), 1)
        self.region_observed = np.zeros(self.region_shape, dtype=np.int64)
        self.region_frontier = np.zeros(self.region_shape, dtype=np.int64)

    #: What a copy shares with its original: the lattice's geometry, fixed at construction, and
    #: caches that are replaced, never changed in place. The lookahead copies the graph a dozen
    #: times a decision; the edge walks alone are megabytes.
    SHARED_ON_COPY = frozenset(
        (
            "spec",
            "lattice_i",
            "lattice_j",
            "node_ij",
            "node_world",
            "node_cells",
            "node_flat",
            "node_count",
            "_id_grid",
            "edge_nodes",
            "_edge_walks",
            "_walk_rows",
            "_edge_box",
            "edge_length",
            "_edge_keys",
            "_edge_order",
            "utility_range_cells",
            "_region_cells",
            "_region_origin",
            "region_col_of_x",
            "region_row_of_y",
            "_region_offset",
            "region_shape",
            "node_region",
            "nodes_per_region",
            "_search_entries",
            "_adjacency",
            "_search_matrix",
            "_neighbour_lists",
        )
    )

    #: Derived from the edges and rebuilt when they change.
    EDGE_CACHES = ("_adjacency", "_search_matrix", "_neighbour_lists", "_edge_cost")

    def state(self) -> dict:
        """What changes with the belief (node states, edges, frontier, utilities, regions): all a
        copy does not share, and all another process holding this lattice needs (`with_state`)."""
        return {name: value for name, value in self.__dict__.items() if name not in self.SHARED_ON_COPY}

    def with_state(self, state: dict) -> "LatticeGraph":
        """A graph on this one's lattice in `state` (from `state()`, maybe another process's)."""
        graph = LatticeGraph.__new__(LatticeGraph)
        graph.__dict__.update({name: value for name, value in self.__dict__.items() if name in self.SHARED_ON_COPY})
        graph.__dict__.update(state)
        graph.__dict__.update(dict.fromkeys(self.EDGE_CACHES))
        return graph

    def __deepcopy__(self, memo: dict) -> "LatticeGraph":
        """A copy whose state (node states, edges, frontier, utilities, regions) is its own."""
        clone = LatticeGraph.__new__(LatticeGraph)
        memo[id(self)] = clone
        for name, value in self.__dict__.items():
            clone.__dict__[name] = value if name in self.SHARED_ON_COPY else copy.deepcopy(value, memo)
        return clone

    # ----------------------------------------------------------------- construction
    @property
    def lattice_shape(self) -> tuple[int, int]:
        """(rows, cols) of the lattice; node ids run row-major over it (rows along y)."""
        return self._id_grid.shape  # type: ignore[return-value]

    def node_id(self, i: int, j: int) -> int:
        """Node id of lattice index (i, j), or -1 outside the lattice."""
        col = i - self.lattice_i[0]
        row = j - self.lattice_j[0]
        if 0 <= row < self._id_grid.shape[0] and 0 <= col < self._id_grid.shape[1]:
            return int(self._id_grid[row, col])
        return -1

    def nearest_node(self, xy: tuple[float, float]) -> int:
        """The lattice node nearest to a world position."""
        i = int(np.round(xy[0] / self.spec.node_resolution))
        j = int(np.round(xy[1] / self.spec.node_resolution))
        i = min(max(i, int(self.lattice_i[0])), int(self.lattice_i[-1]))
        j = min(max(j, int(self.lattice_j[0])), int(self.lattice_j[-1]))
        return self.node_id(i, j)

    def _build_candidate_edges(self) -> None:
        cols = self.spec.shape[1]
        offsets = [
            (di, dj)
            for dj in range(0, WINDOW_RADIUS + 1)
            for di in range(-WINDOW_RADIUS, WINDOW_RADIUS + 1)
            if dj > 0 or di > 0
        ]
        nodes, walks_fwd, walks_bwd, groups = [], [], [], []
        n_rows, n_cols = self._id_grid.shape
        count = 0
        for di, dj in offsets:
            a_rows = slice(max(0, -dj), n_rows - max(0, dj))
            a_cols = slice(max(0, -di), n_cols - max(0, di))
            b_rows = slice(max(0, dj), n_rows - max(0, -dj))
            b_cols = slice(max(0, di), n_cols - max(0, -di))
            a = self._id_grid[a_rows, a_cols].ravel()
            b = self._id_grid[b_rows, b_cols].ravel()
            if a.size == 0:
                continue
            delta = self.node_cells[b] - self.node_cells[a]
            # With a non-integer node step the cell offset can vary; group by offset.
            for dx, dy in np.unique(delta, axis=0):
                sel = (delta[:, 0] == dx) & (delta[:, 1] == dy)
                ea, eb = a[sel], b[sel]
                fwd = walk_offsets(int(dx), int(dy))
                bwd = walk_offsets(int(-dx), int(-dy))
                ca, cb = self.node_cells[ea], self.node_cells[eb]
                walks_fwd.append((ca[:, None, 1] + fwd[None, :, 1]) * cols + ca[:, None, 0] + fwd[None, :, 0])
                walks_bwd.append((cb[:, None, 1] + bwd[None, :, 1]) * cols + cb[:, None, 0] + bwd[None, :, 0])
                nodes.append(np.stack([ea, eb], axis=1))
                groups.append(slice(count, count + len(ea)))
                count += len(ea)
        self.edge_nodes = np.concatenate(nodes) if nodes else np.zeros((0, 2), dtype=np.int64)
        self._edge_walks = list(zip(groups, walks_fwd, walks_bwd))
        # Every edge's two walks as rows of flat cells, padded with -1: the compiled edge test's input.
        longest = max((w.shape[1] for w in walks_fwd), default=0)
        self._walk_rows = np.full((2, len(self.edge_nodes), longest), -1, dtype=np.int32)
        for group, fwd, bwd in self._edge_walks:
            self._walk_rows[0, group, : fwd.shape[1]] = fwd
            self._walk_rows[1, group, : bwd.shape[1]] = bwd
        ends = self.node_cells[self.edge_nodes]
        self._edge_box = np.stack(
            [ends[..., 0].min(1), ends[..., 0].max(1), ends[..., 1].min(1), ends[..., 1].max(1)], axis=1
        )
        diff = self.node_world[self.edge_nodes[:, 1]] - self.node_world[self.edge_nodes[:, 0]]
        self.edge_length = np.hypot(diff[:, 0], diff[:, 1])
        keys = self.edge_nodes.min(axis=1) * self.node_count + self.edge_nodes.max(axis=1)
        self._edge_order = np.argsort(keys, kind="stable")
        self._edge_keys = keys[self._edge_order]  # sorted: an edge found from its two nodes (`edge_between`)
        # Both directions of every candidate edge in `search_matrix`'s order (by row; higher
        # neighbours first, each ascending): (edge, row, column) per entry.
        edge = np.tile(np.arange(len(self.edge_nodes)), 2)
        rows = np.concatenate([self.edge_nodes[:, 0], self.edge_nodes[:, 1]])
        columns = np.concatenate([self.edge_nodes[:, 1], self.edge_nodes[:, 0]])
        order = np.lexsort((columns, columns < rows, rows))
        self._search_entries = (edge[order], rows[order], columns[order].astype(np.int32))

    # ----------------------------------------------------------------- updates
    def update(self, belief: np.ndarray, changed_flat: np.ndarray | None = None) -> None:
        """Bring the graph up to date with `belief` after the cells `changed_flat` changed.

        `changed_flat=None` means everything may have changed (first call).
        """
        self.belief = belief  # the belief this graph reflects (read-only; the node image is drawn from it)
        self._known_free = None
        self.utility_version += 1
        rows, cols = belief.shape
        if changed_flat is None:
            box = (0, cols - 1, 0, rows - 1)
            self.frontier = frontier_mask(belief, self.spec.frontier_min_unknown_neighbours)
            frontier_box = box
        else:
            if len(changed_flat) == 0:
                return
            ys, xs = np.divmod(np.asarray(changed_flat), cols)
            box = (int(xs.min()), int(xs.max()), int(ys.min()), int(ys.max()))
            frontier_box = update_frontier_window(self.frontier, belief, box, self.spec.frontier_min_unknown_neighbours)
        self._update_nodes(belief, box)
        self._update_edges(belief, box)
        self._update_utilities(belief, frontier_box)
        if self.track_regions:
            self._update_regions(belief, frontier_box)

    def _nodes_in_box(self, box: tuple[int, int, int, int], margin: float = 0.0) -> np.ndarray:
        x0, x1, y0, y1 = box
        c = self.node_cells
        inside = (
            (c[:, 0] >= x0 - margin) & (c[:, 0] <= x1 + margin) & (c[:, 1] >= y0 - margin) & (c[:, 1] <= y1 + margin)
        )
        return np.nonzero(inside)[0]

    def _update_nodes(self, belief: np.ndarray, box: tuple[int, int, int, int]) -> None:
        ids = self._nodes_in_box(box)
        self.node_state[ids] = node_states_in(belief, self.node_flat[ids])

    def _update_edges(self, belief: np.ndarray, box: tuple[int, int, int, int]) -> None:
        """An invalid edge whose bounding box meets `box` becomes valid when either of its walks
        crosses only known-free cells (a compiled loop: it ran once per rollout step)."""
        changed = _validate_edges(
            self.edge_valid,
            self._edge_box,
            np.array(box, dtype=np.int64),
            self._walk_rows,
            np.ascontiguousarray(belief).reshape(-1),
            FREE,
        )
        if self.spec.door_radius_cells is not None:
            changed |= self._update_door_edges(belief, box)
        if changed:
            self._adjacency = None
            self._search_matrix = None
            self._neighbour_lists = None
            self._edge_cost = None

    def _update_door_edges(self, belief: np.ndarray, box: tuple[int, int, int, int]) -> bool:
        """Validate through a door node (`pipeline.lattice.doors`) the still-invalid edges between
        known free nodes that meet `box`, and shorten those whose door node the new cells improve
        on; whether any changed. Passability is read in a window around the box wide enough for
        every way round an edge there can take."""
        rows, cols = belief.shape
        step = int(np.ceil(self.spec.node_step_cells))
        radius = float(typing.cast(float, self.spec.door_radius_cells))  # set: the caller checks
        margin = int(np.ceil(MAX_DETOUR * WINDOW_RADIUS * step * np.sqrt(2))) + int(np.ceil(radius)) + 2
        x0, x1, y0, y1 = box
        wx0, wx1, wy0, wy1 = (
            max(0, x0 - margin),
            min(cols, x1 + margin + 1),
            max(0, y0 - margin),
            min(rows, y1 + margin + 1),
        )
        window = belief[wy0:wy1, wx0:wx1]
        clearance = clearance_cells(window)
        passable = (window == FREE) & (clearance >= radius - 1e-6) if radius > 1.0 else window == FREE
        return door_edges_kernel(
            self.edge_valid,
            self.edge_via,
            self.via_length,
            self._edge_box,
            np.array(box, dtype=np.int64),
            self.edge_nodes,
            self.node_cells,
            self.node_state == NODE_FREE,
            np.ascontiguousarray(passable),
            np.ascontiguousarray(clearance, dtype=np.float32),
            wx0,
            wy0,
            cols,
            self.spec.cell_size,
            MAX_DETOUR,
        )

    def edge_between(self, a: int, b: int) -> int:
        """The candidate edge joining nodes `a` and `b`, or -1 when they are not window neighbours."""
        key = min(a, b) * self.node_count + max(a, b)
        at = int(np.searchsorted(self._edge_keys, key))
        return int(self._edge_order[at]) if at < len(self._edge_keys) and self._edge_keys[at] == key else -1

    def route_between(self, a: int, b: int) -> list[tuple[float, float]]:
        """The waypoints (metres) that drive from node `a` to its neighbour `b`: `b`, after the edge's
        door node when the edge is valid through one."""
        edge = self.edge_between(a, b)
        end = (float(self.node_world[b][0]), float(self.node_world[b][1]))
        if edge < 0 or self.edge_via[edge] < 0:
            return [end]
        cols = self.spec.shape[1]
        door = self.spec.cell_to_world(np.array([self.edge_via[edge] % cols, self.edge_via[edge] // cols]))
        return [(float(door[0]), float(door[1])), end]

    @property
    def edge_cost(self) -> np.ndarray:
        """Each candidate edge's length in metres as the robot drives it: straight, or through its door node."""
        if self._edge_cost is None:
            self._edge_cost = np.where(self.edge_via >= 0, self.via_length, self.edge_length)
        return self._edge_cost

    def _update_utilities(self, belief: np.ndarray, box: tuple[int, int, int, int]) -> None:
        """Frontier utility: frontier cells visible (through known-free cells) within range."""
        r = self.utility_range_cells
        near = self._nodes_in_box(box, margin=r + 1)
        self.utility[near] = 0
        self.stale[near] = False
        ids = near[self.node_state[near] == NODE_FREE]
        if ids.size == 0 or not self.frontier.any():
            return
        rows, cols = belief.shape
        # Skip nodes with no frontier cell in their range's bounding square (summed-area table).
        integral = cv2.integral(self.frontier.view(np.uint8))  # (rows + 1, cols + 1) running sums
        rc = int(np.ceil(r))
        c = self.node_cells[ids]
        xa, xb = np.clip(c[:, 0] - rc, 0, cols), np.clip(c[:, 0] + rc + 1, 0, cols)
        ya, yb = np.clip(c[:, 1] - rc, 0, rows), np.clip(c[:, 1] + rc + 1, 0, rows)
        in_square = integral[yb, xb] - integral[ya, xb] - integral[yb, xa] + integral[ya, xa]
        ids, in_square = ids[in_square > 0], in_square[in_square > 0]
        if ids.size == 0:
            return
        if self.lazy_utilities:  # the square holds every frontier cell the fan can see: a bound
            self.utility[ids] = in_square
            self.stale[ids] = True
            return
        self.utility[ids] = visible_counts(belief == FREE, self.frontier, self.node_cells[ids], r)

    def exact_utilities(self, nodes: np.ndarray) -> None:
        """Count the visible frontier of those of `nodes` whose utility is still a bound. The count
        on the current belief is the one at the update that left the bound: any later change in
        the node's range would have set a new bound."""
        todo = nodes[self.stale[nodes]]
        if todo.size:
            if self._known_free is None:
                self._known_free = self.belief == FREE
            self.utility[todo] = visible_counts(
                self._known_free, self.frontier, self.node_cells[todo], self.utility_range_cells
            )
            self.stale[todo] = False
            self.utility_version += 1

    def _update_regions(self, belief: np.ndarray, box: tuple[int, int, int, int]) -> None:
        x0, x1, y0, y1 = box
        rc0, rc1 = self.region_col_of_x[x0], self.region_col_of_x[x1]
        rr0, rr1 = self.region_row_of_y[y0], self.region_row_of_y[y1]
        xs = np.nonzero((self.region_col_of_x >= rc0) & (self.region_col_of_x <= rc1))[0]
        ys = np.nonzero((self.region_row_of_y >= rr0) & (self.region_row_of_y <= rr1))[0]
        sub_known = belief[ys[0] : ys[-1] + 1, xs[0] : xs[-1] + 1] != UNKNOWN
        sub_front = self.frontier[ys[0] : ys[-1] + 1, xs[0] : xs[-1] + 1]
        ry = self.region_row_of_y[ys[0] : ys[-1] + 1]
        rx = self.region_col_of_x[xs[0] : xs[-1] + 1]
        shape = (rr1 - rr0 + 1, rc1 - rc0 + 1)
        flat = ((ry[:, None] - rr0) * shape[1] + (rx[None, :] - rc0)).ravel()
        size = shape[0] * shape[1]
        known = np.bincount(flat, weights=sub_known.ravel(), minlength=size).reshape(shape)
        front = np.bincount(flat, weights=sub_front.ravel(), minlength=size).reshape(shape)
        self.region_observed[rr0 : rr1 + 1, rc0 : rc1 + 1] = known.astype(np.int64)
        self.region_frontier[rr0 : rr1 + 1, rc0 : rc1 + 1] = front.astype(np.int64)

    # ----------------------------------------------------------------- queries
    @property
    def free_nodes(self) -> np.ndarray:
        """Ids of the known free nodes V_f."""
        return np.nonzero(self.node_state == NODE_FREE)[0]

    @property
    def edges(self) -> np.ndarray:
        """Valid undirected edges (a, b) between known free nodes."""
        return self.edge_nodes[self.edge_valid]

    def neighbours(self, node: int) -> np.ndarray:
        """Nodes joined to `node` by a known-free edge, in id order."""
        if self._neighbour_lists is None:  # both directions of the adjacency, built once per graph change
            both = self.adjacency() + self.adjacency().T
            self._neighbour_lists = (both.indptr, both.indices)
        indptr, indices = self._neighbour_lists
        return np.sort(indices[indptr[node] : indptr[node + 1]])

    def adjacency(self):
        """Sparse adjacency matrix (upper triangle) weighted by edge length in metres."""
        if self._adjacency is None:
            e = self.edge_nodes[self.edge_valid]
            w = self.edge_cost[self.edge_valid]
            self._adjacency = coo_matrix((w, (e[:, 0], e[:, 1])), shape=(self.node_count,) * 2).tocsr()
        return self._adjacency

    def shortest_paths(self, source: int) -> tuple[np.ndarray, np.ndarray]:
        """Distances (metres, inf if unreachable) and predecessors from `source`.

        The same search as scipy's undirected Dijkstra on `adjacency()`, run as a directed one
        on `search_matrix()`: undirected, scipy transposes the matrix at every call, a third of
        the lookahead's rollout time in shortest paths.
        """
        dist, pred = dijkstra(self.search_matrix(), directed=True, indices=source, return_predecessors=True)
        return dist, pred

    def search_matrix(self) -> csr_matrix:
        """Both directions of every valid edge, each node's row listing its higher-id neighbours
        first and then its lower-id ones, each ascending: the order in which scipy's undirected
        Dijkstra scans a node's edges (the upper-triangle row, then the transpose's). Scanned in
        that order, ties between equally long paths resolve as they do undirected: the same
        distances and the same predecessors. Built once per change of the edges."""
        if self._search_matrix is None:
            edge, rows, cols = self._search_entries
            keep = self.edge_valid[edge]
            indptr = np.zeros(self.node_count + 1, dtype=np.int32)
            np.cumsum(np.bincount(rows[keep], minlength=self.node_count), out=indptr[1:])
            self._search_matrix = csr_matrix(
                (self.edge_cost[edge[keep]], cols[keep], indptr), shape=(self.node_count,) * 2
            )
        return self._search_matrix

    @staticmethod
    def path_from_predecessors(predecessors: np.ndarray, target: int) -> list[int]:
        """Node ids from the source to `target` (inclusive), [] if unreachable."""
        path = [int(target)]
        while predecessors[path[-1]] >= 0:
            path.append(int(predecessors[path[-1]]))
        path.reverse()
        return path

    def region_of_cells(self, cells: np.ndarray) -> np.ndarray:
        """(region row, region col) of each cell (x, y)."""
        cells = np.asarray(cells)
        return np.stack([self.region_row_of_y[cells[:, 1]], self.region_col_of_x[cells[:, 0]]], axis=1)

    def edges_not_crossing(
        self, blocked_flat: np.ndarray, members: np.ndarray, required: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Candidate edges between `members` nodes, touching a `required` node, whose walk
        (either direction) crosses no `blocked_flat` cell; returns (pairs, lengths in metres).

        This is how predicted nodes join the global graph: through unknown space, never
        through known obstacles.
        """
        pairs, lengths = [], []
        for group, fwd, bwd in self._edge_walks:
            ends = self.edge_nodes[group]
            cand = members[ends[:, 0]] & members[ends[:, 1]] & (required[ends[:, 0]] | required[ends[:, 1]])
            idx = np.nonzero(cand)[0]
            if idx.size == 0:
                continue
            ok = ~blocked_flat[fwd[idx]].any(axis=1) | ~blocked_flat[bwd[idx]].any(axis=1)
            pairs.append(ends[idx[ok]])
            lengths.append(self.edge_length[group][idx[ok]])
        if not pairs:
            return np.zeros((0, 2), dtype=np.int64), np.zeros(0)
        return np.concatenate(pairs), np.concatenate(lengths)

    def region_labels(self) -> np.ndarray:
        """Per region: UNOBSERVED (nothing known), BOUNDARY (has frontiers), else EXPLORED."""
        labels = np.full(self.region_shape, REGION_EXPLORED, dtype=np.int8)
        labels[self.region_observed == 0] = REGION_UNOBSERVED
        labels[self.region_frontier > 0] = REGION_BOUNDARY
        return labels

    def region_centroids(self) -> np.ndarray:
        """World centres (x, y) of every region, shape region_shape + (2,)."""
        rows, cols = self.region_shape
        rc = self._region_cells
        ox, oy = self._region_offset
        cx = ((np.arange(cols) + ox + 0.5) * rc) * self.spec.cell_size
        cy = ((np.arange(rows) + oy + 0.5) * rc) * self.spec.cell_size
        return np.stack(np.meshgrid(cx, cy, indexing="xy"), axis=-1)

    def unobserved_centroids(self) -> np.ndarray:
        """V_g: centroids (x, y) of the unobserved regions, standing in for unknown space."""
        return self.region_centroids()[self.region_labels() == REGION_UNOBSERVED]


@numba.njit(cache=True, nogil=True)
def _validate_edges(valid, edge_box, box, walk_rows, belief_flat, free_value):  # pragma: no cover - compiled
    """Mark valid the invalid edges meeting `box` (x0, x1, y0, y1) with a walk all `free_value`; whether any was."""
    x0, x1, y0, y1 = box[0], box[1], box[2], box[3]
    changed = False
    for e in range(valid.shape[0]):
        if valid[e] or edge_box[e, 0] > x1 or edge_box[e, 1] < x0 or edge_box[e, 2] > y1 or edge_box[e, 3] < y0:
            continue
        for direction in range(2):
            clear = True
            for k in range(walk_rows.shape[2]):
                cell = walk_rows[direction, e, k]
                if cell < 0:
                    break
                if belief_flat[cell] != free_value:
                    clear = False
                    break
            if clear:
                valid[e] = True
                changed = True
                break
    return changed
