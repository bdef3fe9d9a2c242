"""TARE (Cao et al., RSS 2021): hierarchical exploration, adapted to the node lattice.

TARE plans at two levels and joins them into one route, which it replans continually:

- **Global level.** Space is split into subspaces; those that still hold something to
  explore are "exploring". A TSP tour from the robot visits them in order, over distances
  in the known traversable graph.
- **Local level.** Inside a local planning horizon around the robot, TARE chooses a small
  set of viewpoints that together cover the uncovered surfaces there, and orders them with
  a TSP path that starts at the robot and leaves the horizon toward the first exploring
  subspace of the global tour.

Adaptation to the lattice graph and the protocol:

- What is covered: frontier cells (the 2D stand-in for TARE's uncovered surfaces). A node
  "sees" the frontier cells its ray fan reaches through known-free cells within the
  utility range -- the fan of the graph's utility (`visible_frontier_cells`). As in TARE,
  what has been seen from where the robot has been counts as covered and is no longer
  planned for (`cover_range`, the utility range by default): frontier that stays after
  the robot looked at it from close by (grazing rays past wall corners) cannot be cleared
  by more viewpoints like those, and chasing it would send the robot back and forth.
- Candidate viewpoints are the *useful* nodes (`GraphPlanner.useful_nodes`: unvisited free
  nodes with frontier utility) reachable on the known graph.
- Subspaces are the graph's fixed region grid (`region_size`, 20 m by default). The local
  horizon is the robot's region and its neighbours (`horizon_radius = 1`: 3 x 3 regions).
  An uncovered frontier cell belongs to the local level when it lies in the horizon, else
  to the global level through the region it lies in.
- Global level: a region outside the horizon is exploring when some candidate sees at
  least `min_cover` of its uncovered frontier cells; its representative is the nearest
  such candidate along the graph from the robot. The global tour is an open TSP path from
  the robot through the representatives.
- Local level: greedy set cover of the horizon's uncovered frontier cells by the
  candidates (the most newly covered cells first, the nearer node on a tie) while a
  viewpoint adds at least `min_cover` cells; the viewpoints are ordered by a TSP path from
  the robot that ends at the first representative of the global tour (open when the
  global tour is empty).
- Distances are shortest paths on the known graph (one multi-source Dijkstra per
  decision). TSP paths have a fixed start (and end): exact Held-Karp up to `exact_max`
  points, otherwise nearest-neighbour construction improved by 2-opt and Or-opt moves
  under a move cap, so every decision is bounded in time and deterministic.
- Execution: one lattice step (one graph edge) along the shortest path to the first point
  of the local path, or of the global tour when the horizon holds no viewpoint, and a new
  plan at every decision. With neither (only covered frontier left), one step toward the
  nearest useful node, so the map is finished; [] only when no useful node is reachable.
- Loop guard (not in TARE, which plans in continuous space at a fixed rate): because the
  horizon moves with the robot, a replanned route can flip at a region border although
  nothing new was seen, and the robot would step back and forth. When the new first step
  goes back onto a node visited since the belief last changed, the planner keeps driving
  to its previous target while that one still has uncovered frontier to see.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from scipy.sparse.csgraph import dijkstra

from pipeline.common.config import config_dataclass, flag, maybe, real, whole
from pipeline.lattice.tsp import tsp_path
from pipeline.lattice.visibility import utility_fan
from pipeline.planners.config import option
from pipeline.planners.graph_planner import GraphPlanner, LatticePlannerConfig
from pipeline.planners.registry import register_planner
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE


# --------------------------------------------------------------------------- visibility
def visible_frontier_cells(
    free: np.ndarray, frontier: np.ndarray, origins: np.ndarray, range_cells: float, chunk: int = 64
) -> list[np.ndarray]:
    """For each origin cell (col, row), the sorted flat indices of the `frontier` cells it sees.

    The ray fan is the graph utility's (`pipeline.lattice.visibility.visible_counts`): a ray walks from
    the origin and stops at the first cell that is not free (or outside the grid); the
    cells before that are visible. So `len(result[k])` equals `visible_counts(...)[k]`.
    """
    rows, cols = free.shape
    origins = np.asarray(origins, dtype=np.int64).reshape(-1, 2)
    table = utility_fan(float(range_cells))
    offsets, valid = table.offsets, table.valid
    pad = int(np.abs(offsets).max()) + 1
    # Padded with blocked cells, so a ray that leaves the grid stops there with no bounds checks.
    pcols = cols + 2 * pad
    open_cells = np.zeros((rows + 2 * pad, pcols), dtype=bool)
    open_cells[pad : pad + rows, pad : pad + cols] = free
    targets = np.zeros_like(open_cells)
    targets[pad : pad + rows, pad : pad + cols] = frontier
    open_flat, target_flat = open_cells.reshape(-1), targets.reshape(-1)
    step = offsets[..., 1] * pcols + offsets[..., 0]
    out: list[np.ndarray] = []
    for start in range(0, len(origins), chunk):
        org = origins[start : start + chunk]
        n = len(org)
        base = (org[:, 1] + pad) * pcols + org[:, 0] + pad
        idx = base[:, None, None] + step[None]
        reach = np.logical_and.accumulate(open_flat[idx] & valid[None], axis=2)
        k, ray, i = np.nonzero(reach & target_flat[idx])
        py, px = np.divmod(idx[k, ray, i], pcols)
        key = np.unique(k * (rows * cols) + (py - pad) * cols + (px - pad))
        owner, cell = np.divmod(key, rows * cols)
        bounds = np.searchsorted(owner, np.arange(n + 1))
        out.extend(cell[bounds[j] : bounds[j + 1]] for j in range(n))
    return out


# --------------------------------------------------------------------------- planner
def greedy_set_cover(cover: list[np.ndarray], tie_cost: np.ndarray, min_cover: int) -> list[int]:
    """Indices of sets chosen greedily: each time the set adding the most uncovered
    elements (the lowest `tie_cost` on a tie), while it adds at least `min_cover`."""
    if not cover:
        return []
    universe, inverse = np.unique(np.concatenate(cover + [np.zeros(0, np.int64)]), return_inverse=True)
    if universe.size == 0:
        return []
    member = np.zeros((len(cover), universe.size), dtype=bool)
    rows = np.repeat(np.arange(len(cover)), [len(c) for c in cover])
    member[rows, inverse] = True
    covered = np.zeros(universe.size, dtype=bool)
    chosen: list[int] = []
    while True:
        gains = (member & ~covered[None, :]).sum(axis=1)
        gains[chosen] = 0
        top = gains.max()
        if top < max(1, min_cover):
            break
        best = int(np.lexsort((tie_cost, -gains))[0])
        chosen.append(best)
        covered |= member[best]
    return chosen


@config_dataclass
class TareConfig(LatticePlannerConfig):
    description = (
        "Cao 2021 TARE: global TSP tour over exploring regions, greedy set-cover viewpoints in "
        "the 3x3-region local horizon ordered by a TSP path that joins the global tour"
    )

    horizon_radius: Annotated[int, whole(0, note="0 = the robot's region only")] = option(
        1, "regions around the robot's in the local horizon (1: 3 x 3 regions; 0: its own)"
    )
    min_cover: Annotated[int, whole(1)] = option(
        2, "frontier cells a viewpoint (or an exploring region) must add to count"
    )
    cover_range: Annotated[float | None, maybe(real(0.0, note="0 = off"), "the utility range")] = option(
        None,
        "metres: frontier seen from this close to where the robot was counts as covered (0 = off) [default: the "
        "utility range]",
    )
    exact_max: Annotated[int, whole(1, 14)] = option(
        10, "TSP paths are exact (Held-Karp) up to this many points, else heuristic"
    )
    max_moves: Annotated[int, whole(0, note="0 = no 2-opt / Or-opt moves")] = option(
        200, "at most this many 2-opt / Or-opt moves per heuristic TSP path (0 = none)"
    )
    loop_guard: Annotated[bool, flag()] = option(
        True, "back at a node with nothing new seen, keep the target chosen there"
    )


@register_planner("tare", TareConfig)
class TarePlanner(GraphPlanner):
    """TARE's hierarchy on the lattice: a global TSP tour over exploring regions and a local
    set cover of viewpoints in a 3 x 3-region horizon, ordered by a TSP path joined to it."""

    description = TareConfig.description

    def __init__(self, config: TareConfig = TareConfig()):
        super().__init__(config)
        horizon_radius, min_cover, cover_range = config.horizon_radius, config.min_cover, config.cover_range
        exact_max, max_moves, loop_guard = config.exact_max, config.max_moves, config.loop_guard
        self.horizon_radius = int(horizon_radius)
        self.min_cover = int(min_cover)
        self.cover_range = None if cover_range is None else float(cover_range)
        self.exact_max = int(exact_max)
        self.max_moves = int(max_moves)
        self.loop_guard = bool(loop_guard)
        self.last_decision: dict = {}

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        super().reset(frame, protocol, seed)
        graph = self.graph
        assert graph is not None
        self._region_cols = graph.region_shape[1]
        self._covered = np.zeros(frame.shape[0] * frame.shape[1], dtype=bool)
        self._views: dict[int, np.ndarray] = {}
        self._target = -1
        self._quiet: set[int] = set()
        self.last_decision = {}

    # ----------------------------------------------------------------- coverage
    def _forget_views(self, changed: np.ndarray | None, shape: tuple[int, int]) -> None:
        """Drop cached visible-frontier sets of nodes whose fan may reach a changed cell."""
        if changed is None:
            self._views.clear()
            return
        if len(changed) == 0 or not self._views:
            return
        assert self.graph is not None
        ys, xs = np.divmod(np.asarray(changed), shape[1])
        margin = self.graph.utility_range_cells + 2  # a cell's frontier status depends on its neighbours
        nodes = np.fromiter(self._views.keys(), dtype=np.int64, count=len(self._views))
        c = self.graph.node_cells[nodes]
        stale = (
            (c[:, 0] >= xs.min() - margin)
            & (c[:, 0] <= xs.max() + margin)
            & (c[:, 1] >= ys.min() - margin)
            & (c[:, 1] <= ys.max() + margin)
        )
        for node in nodes[stale]:
            del self._views[int(node)]

    def _visible(self, nodes: np.ndarray, belief: np.ndarray) -> list[np.ndarray]:
        """Frontier cells each node sees within the utility range (cached between decisions)."""
        assert self.graph is not None
        missing = [int(n) for n in nodes if int(n) not in self._views]
        if missing:
            sets = visible_frontier_cells(
                belief == FREE, self.graph.frontier, self.graph.node_cells[missing], self.graph.utility_range_cells
            )
            self._views.update(zip(missing, sets))
        return [self._views[int(n)] for n in nodes]

    def _mark_covered(self, robot: int, belief: np.ndarray) -> None:
        """TARE's covered surfaces: frontier cells seen from a place the robot has been."""
        assert self.graph is not None
        if self.cover_range is None:
            seen = self._visible(np.array([robot]), belief)[0]
        elif self.cover_range > 0:
            range_cells = self.cover_range / self.graph.spec.cell_size
            origin = self.graph.node_cells[[robot]]
            (seen,) = visible_frontier_cells(belief == FREE, self.graph.frontier, origin, range_cells)
        else:
            return
        self._covered[seen] = True

    # ----------------------------------------------------------------- decision
    def plan(self, observation: Observation) -> list[Waypoint]:
        graph = self.update_graph(observation)
        belief = observation.belief
        self._forget_views(observation.changed, belief.shape)
        robot = self.robot_node(observation)
        if observation.changed is None or len(observation.changed) > 0:
            self._quiet = set()  # nodes visited since the belief last changed
        self._quiet.add(robot)
        self._mark_covered(robot, belief)

        dist_robot, pred_robot = graph.shortest_paths(robot)
        useful = self.reachable_useful(robot, dist_robot)
        if useful.size == 0:
            self.last_decision = {"mode": "done"}
            return []

        # Uncovered frontier cells each useful node sees, split into the horizon's and the rest.
        views = [v[~self._covered[v]] for v in self._visible(useful, belief)]
        cols = belief.shape[1]
        r0, c0 = graph.node_region[robot]
        hrows = np.abs(graph.region_row_of_y - r0) <= self.horizon_radius
        hcols = np.abs(graph.region_col_of_x - c0) <= self.horizon_radius
        sizes = np.array([len(v) for v in views])
        owner = np.repeat(np.arange(len(useful)), sizes)
        cells = np.concatenate(views + [np.zeros(0, np.int64)])
        cy, cx = np.divmod(cells, cols)
        inside = hrows[cy] & hcols[cx]

        # Global level: exploring subspaces are the regions outside the horizon whose uncovered
        # frontier cells some node sees at least `min_cover` of; each is represented by the
        # nearest such node (along the graph from the robot).
        reps = np.zeros(0, dtype=np.int64)
        if (~inside).any():
            key = graph.region_row_of_y[cy[~inside]] * self._region_cols + graph.region_col_of_x[cx[~inside]]
            base = int(key.max()) + 1
            pair, count = np.unique(owner[~inside] * base + key, return_counts=True)
            pair = pair[count >= self.min_cover]
            if pair.size:
                node_k, key_k = np.divmod(pair, base)
                node_k = useful[node_k]
                by_region = np.lexsort((node_k, dist_robot[node_k], key_k))  # per region, nearest first
                key_sorted = key_k[by_region]
                first = np.ones(len(by_region), dtype=bool)
                first[1:] = key_sorted[1:] != key_sorted[:-1]
                reps = np.unique(node_k[by_region[first]])

        # Local level: greedy set cover of the uncovered frontier cells in the horizon.
        viewpoints = np.zeros(0, dtype=np.int64)
        if inside.any():
            bounds = np.concatenate([[0], np.cumsum(sizes)])
            sets = [cells[bounds[k] : bounds[k + 1]][inside[bounds[k] : bounds[k + 1]]] for k in range(len(useful))]
            viewpoints = useful[greedy_set_cover(sets, dist_robot[useful], self.min_cover)]

        # Shortest-path distances between all tour points: one Dijkstra from each.
        points = np.unique(np.concatenate([[robot], reps, viewpoints]))
        rows = dijkstra(graph.adjacency(), directed=False, indices=points)
        row_of = {int(p): k for k, p in enumerate(points)}

        def matrix(nodes: np.ndarray) -> np.ndarray:
            d = rows[[row_of[int(x)] for x in nodes]][:, nodes]
            return np.minimum(d, d.T)  # exactly symmetric for the TSP moves

        global_tour: list[int] = []
        if reps.size:
            nodes = np.concatenate([[robot], reps])
            order = tsp_path(matrix(nodes), None, self.exact_max, self.max_moves)
            global_tour = [int(nodes[k]) for k in order[1:]]

        # The local path starts at the robot and ends at the first exploring subspace of
        # the global tour (open when there is none).
        local_tour: list[int] = []
        if viewpoints.size:
            if global_tour:
                nodes = np.concatenate([[robot], viewpoints[viewpoints != global_tour[0]], [global_tour[0]]])
                order = tsp_path(matrix(nodes), len(nodes) - 1, self.exact_max, self.max_moves)
            else:
                nodes = np.concatenate([[robot], viewpoints])
                order = tsp_path(matrix(nodes), None, self.exact_max, self.max_moves)
            local_tour = [int(nodes[k]) for k in order[1:]]

        if local_tour:
            target, mode = local_tour[0], "local"
        elif global_tour:
            target, mode = global_tour[0], "global"
        else:
            target, mode = int(useful[np.lexsort((useful, dist_robot[useful]))[0]]), "nearest"
        path = graph.path_from_predecessors(pred_robot, target)

        # Loop guard (not in TARE): with no new information since the robot stepped onto a
        # node, a replanned route can still flip as the horizon moves with the robot. When
        # the new first step would go back onto a node visited since the belief last
        # changed, keep driving to the previous target while it is still worth a visit.
        if self.loop_guard and target != self._target and path[1] in self._quiet:
            k = np.nonzero(useful == self._target)[0]
            if k.size and len(views[int(k[0])]) >= self.min_cover:
                target, mode = self._target, "kept"
                path = graph.path_from_predecessors(pred_robot, target)
        self._target = target
        self.last_decision = {"mode": mode, "target": target, "local_tour": local_tour, "global_tour": global_tour}
        return self.waypoints_along(path)
