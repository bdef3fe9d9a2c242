"""The observed graph as the `dare` planner's policy sees it, built straight from the lattice graph:
what the Gymnasium environment observes and the `drl` planner decides on.

`pipeline.prediction.graph_observation.observe` on a `GlobalGraph` updated without predictions
(`use_region_evaluation=False`) gives the learned planners' observation of the known graph:
padded node features, a node mask, neighbour lists and the robot's row. Without predictions
that global graph is the lattice graph's known free nodes and known-free edges, so the same
arrays can be read off the lattice graph directly, with each node's 5 x 5 window laid out
once as a table: no global graph is rebuilt at every step, and the neighbour lists are filled
from the table by one compiled loop rather than row by row in Python. The arrays are those
`observe` returns (tests/envs check them against it, step by step); the environment's action
masks and node-action paths come from the same shortest-path search.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba
import numpy as np

from pipeline.lattice.graph import NODE_FREE, WINDOW_RADIUS, LatticeGraph
from pipeline.prediction.global_graph import FEATURE_NAMES, GlobalGraphConfig

WINDOW = 2 * WINDOW_RADIUS + 1
SLOTS = WINDOW * WINDOW  # neighbour-action slots: the lattice offsets of the 5 x 5 window, row-major
STAY_SLOT = SLOTS // 2  # the centre: no move
SLOT_OFFSETS = np.array(
    [(dx, dy) for dy in range(-WINDOW_RADIUS, WINDOW_RADIUS + 1) for dx in range(-WINDOW_RADIUS, WINDOW_RADIUS + 1)],
    dtype=np.int64,
)  # (dx, dy) per slot


def slot_of_offset(dx: int, dy: int) -> int:
    """The action slot of lattice offset (dx, dy), each in -2..2: (dy + 2) * 5 + (dx + 2)."""
    if abs(dx) > WINDOW_RADIUS or abs(dy) > WINDOW_RADIUS:
        raise ValueError(f"lattice offset ({dx}, {dy}) lies outside the {WINDOW} x {WINDOW} window")
    return (dy + WINDOW_RADIUS) * WINDOW + (dx + WINDOW_RADIUS)


class WindowTable:
    """Each lattice node's window: per slot, the neighbour's node id and their candidate edge (-1 if none).

    Fixed by the lattice's geometry; the edges' validity is read from the graph at each step.
    """

    def __init__(self, graph: LatticeGraph):
        count = graph.node_count
        self.neighbour = np.full((count, SLOTS), -1, dtype=np.int64)
        self.edge = np.full((count, SLOTS), -1, dtype=np.int64)
        a, b = graph.edge_nodes[:, 0], graph.edge_nodes[:, 1]
        delta = graph.node_ij[b] - graph.node_ij[a]
        forward = (delta[:, 1] + WINDOW_RADIUS) * WINDOW + delta[:, 0] + WINDOW_RADIUS
        backward = (SLOTS - 1) - forward  # the opposite offset
        edges = np.arange(len(a))
        self.neighbour[a, forward], self.edge[a, forward] = b, edges
        self.neighbour[b, backward], self.edge[b, backward] = a, edges
        # The same tables with the slots in ascending order of their neighbour's id: `observe`'s order.
        columns = graph.lattice_shape[1]
        id_order = np.argsort(SLOT_OFFSETS[:, 1] * columns + SLOT_OFFSETS[:, 0], kind="stable")
        self.neighbour_by_id = np.ascontiguousarray(self.neighbour[:, id_order])
        self.edge_by_id = np.ascontiguousarray(self.edge[:, id_order])


def window_moves(graph: LatticeGraph, table: WindowTable, node: int) -> np.ndarray:
    """Per action slot of `node`'s 5 x 5 window, whether a known-free edge leads there (bool, SLOTS)."""
    edges = table.edge[node]
    return (edges >= 0) & graph.edge_valid[np.maximum(edges, 0)]


@dataclass
class ObservedStep:
    """One step's padded observation of the observed graph, and the search it was built with."""

    features: np.ndarray  # (max_nodes, len(FEATURE_NAMES)) float32
    node_mask: np.ndarray  # (max_nodes,) bool
    neighbors: np.ndarray  # (max_nodes, max_neighbors) int16, rows, -1 padded
    robot_row: int  # the robot's row
    row_nodes: np.ndarray  # lattice node id of each filled row, nearest the robot first
    robot_node: int  # the robot's lattice node
    distance: np.ndarray  # known-graph distance (m) from the robot to every lattice node (inf: unreachable)
    predecessors: np.ndarray  # their shortest-path predecessors (LatticeGraph.shortest_paths)


def observe_lattice(
    graph: LatticeGraph,
    table: WindowTable,
    robot_xy,
    visited: np.ndarray,
    config: GlobalGraphConfig,
    max_neighbors: int,
) -> ObservedStep:
    """`observe(GlobalGraph(graph, config) updated with no predictions, robot_xy, max_neighbors)`
    computed from the lattice graph; `visited` marks the lattice nodes the robot has stood on."""
    robot_xy = np.asarray(robot_xy, dtype=np.float64)
    known = np.flatnonzero(graph.node_state == NODE_FREE)
    positions = graph.node_world[known]
    distance_to_robot = np.hypot(*(positions - robot_xy).T)
    robot = int(known[np.argmin(distance_to_robot)])
    order = np.argsort(distance_to_robot, kind="stable")[: config.max_nodes]  # rows, as indices into `known`
    row_nodes = known[order]
    distance, predecessors = graph.shortest_paths(robot)

    # Utility: the frontier count, capped as the global graph caps its boosted utility (no boost here).
    utility = graph.utility[known].astype(np.float64)
    active = utility > 0
    utility[active] = np.minimum(2.0 * np.pi * graph.spec.utility_range / graph.spec.cell_size, utility[active])
    # Guidepost: the shortest path to the nearest reachable unvisited node worth a visit.
    guidepost = np.zeros(graph.node_count, dtype=bool)
    known_distance = distance[known]
    reachable_unvisited = np.isfinite(known_distance) & ~visited[known]
    useful = np.flatnonzero(reachable_unvisited & (utility >= config.guidepost_min_utility))
    if useful.size == 0:
        useful = np.flatnonzero(reachable_unvisited & (utility > 0))
    if useful.size:
        node = int(known[useful[np.argmin(known_distance[useful])]])
        while node >= 0:
            guidepost[node] = True
            node = int(predecessors[node])

    n_max, filled = config.max_nodes, len(order)
    features = np.zeros((n_max, len(FEATURE_NAMES)), dtype=np.float32)
    features[:filled, 0:2] = (positions[order] - robot_xy) / (config.position_scale_nodes * graph.spec.node_resolution)
    features[:filled, 2] = np.minimum(utility[order] / config.utility_scale, 1.0)
    features[:filled, 3] = guidepost[row_nodes]
    features[:filled, 4] = visited[row_nodes]
    node_mask = np.zeros(n_max, dtype=bool)
    node_mask[:filled] = True
    robot_row = int(np.flatnonzero(row_nodes == robot)[0])
    neighbors = _neighbour_rows(graph, table, row_nodes, n_max, max_neighbors)
    return ObservedStep(features, node_mask, neighbors, robot_row, row_nodes, robot, distance, predecessors)


def _neighbour_rows(
    graph: LatticeGraph, table: WindowTable, row_nodes: np.ndarray, n_max: int, max_neighbors: int
) -> np.ndarray:
    """Per row, the rows of its known-graph neighbours in ascending node id; a row with more than
    `max_neighbors` keeps the nearest (by edge length, ties by id), as `observe` does."""
    row_of = np.full(graph.node_count, -1, dtype=np.int64)
    row_of[row_nodes] = np.arange(len(row_nodes))
    neighbors = np.full((n_max, max_neighbors), -1, dtype=np.int16)
    counts = _fill_neighbour_rows(
        neighbors, row_nodes, row_of, table.edge_by_id, table.neighbour_by_id, graph.edge_valid
    )
    for r in np.flatnonzero(counts > max_neighbors):  # only when max_neighbors is below the window's 24
        edges, nodes = table.edge_by_id[row_nodes[r]], table.neighbour_by_id[row_nodes[r]]
        kept = np.flatnonzero((edges >= 0) & graph.edge_valid[edges] & (row_of[nodes] >= 0))
        nearest = kept[np.argsort(graph.edge_cost[edges[kept]], kind="stable")[:max_neighbors]]
        neighbors[r] = row_of[nodes[nearest]]
    return neighbors


@numba.njit(cache=True, nogil=True)
def _fill_neighbour_rows(out, row_nodes, row_of, edge, neighbour, edge_valid):  # pragma: no cover - compiled
    """Write each row's neighbour rows (slots in id order: valid edge, neighbour among the rows) into
    `out` up to its width; return how many each row has in all."""
    counts = np.zeros(len(row_nodes), np.int64)
    width = out.shape[1]
    for r in range(len(row_nodes)):
        node = row_nodes[r]
        k = 0
        for s in range(edge.shape[1]):
            e = edge[node, s]
            if e < 0 or not edge_valid[e]:
                continue
            row = row_of[neighbour[node, s]]
            if row < 0:
                continue
            if k < width:
                out[r, k] = row
            k += 1
        counts[r] = k
    return counts
