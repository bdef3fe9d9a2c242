"""The policy's view of one step: padded node features, neighbour lists, the robot's row.

DARE's observation, which GUIDE extends with type flags: per node (dx, dy relative to the
robot / scale, utility, guidepost, visited, is_predicted, is_centroid), padded to a fixed
node count with a validity mask, and each node's neighbours as a fixed-width index list
(-1 padded) from which the encoder builds its attention mask. Expert actions are the next
T_p lattice steps in node units, each within the 5 x 5 edge window.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import cast

import numpy as np

from pipeline.prediction.global_graph import GlobalGraph


@dataclass
class GraphObservation:
    """One step's padded graph: arrays sized by (max_nodes, max_neighbors)."""

    features: np.ndarray  # (N, F) float32
    node_mask: np.ndarray  # (N,) bool
    neighbors: np.ndarray  # (N, M) int16, -1 padded; indices into the padded rows
    robot: int  # the robot's row
    positions: np.ndarray  # (N, 2) world metres of each row (NaN for padding); not a model input


def observe(graph: GlobalGraph, robot_xy, max_neighbors: int = 25) -> GraphObservation:
    """The padded observation of `graph` (its config's max_nodes, nearest nodes first)."""
    features, mask, robot_row = graph.features(robot_xy)
    n_max = len(mask)
    order = graph.row_order(robot_xy)
    row_of = np.full(graph.node_count, -1, dtype=np.int64)
    row_of[order] = np.arange(len(order))
    neighbors = np.full((n_max, max_neighbors), -1, dtype=np.int16)
    # The adjacency may hold an undirected edge once or both ways: symmetrise.
    sym = (graph.adjacency + graph.adjacency.T).tocsr()
    indptr, indices, weights = sym.indptr, sym.indices, sym.data
    for row, node in enumerate(order):
        cols = indices[indptr[node] : indptr[node + 1]]
        w = weights[indptr[node] : indptr[node + 1]]
        rows = row_of[cols]
        keep = rows >= 0
        rows, w = rows[keep], w[keep]
        if len(rows) > max_neighbors:
            rows = rows[np.argsort(w, kind="stable")[:max_neighbors]]
        neighbors[row, : len(rows)] = rows
    positions = np.full((n_max, 2), np.nan)
    positions[: len(order)] = graph.positions[order]
    return GraphObservation(features.astype(np.float32), mask, neighbors, int(robot_row), positions)


def expert_action_deltas(position, future_waypoints: np.ndarray, node_resolution: float, limit: int = 2) -> np.ndarray:
    """(T_p, 2) lattice steps in node units between consecutive future waypoints.

    Waypoints past the end of an episode are stored as NaN (or repeat the last one): those
    steps are 0 (stay), as Diffusion Policy pads its action chunks.
    """
    points = np.vstack([np.asarray(position, dtype=np.float64)[None], np.asarray(future_waypoints, dtype=np.float64)])
    valid = cast(np.ndarray, np.isfinite(points).all(axis=1))
    for k in range(1, len(points)):  # carry the last valid point forward
        if not valid[k]:
            points[k] = points[k - 1]
    steps = np.rint(np.diff(points, axis=0) / node_resolution).astype(np.int64)
    if np.abs(steps).max(initial=0) > limit:
        raise ValueError(
            f"an expert step {steps[np.abs(steps).max(axis=1) > limit][0].tolist()} leaves the {2 * limit + 1}x{2 * limit + 1} window"
        )
    return steps


def rotate_steps(steps: np.ndarray, k: int, flip: bool) -> np.ndarray:
    """The dihedral symmetry (k quarter turns, then an optional x flip) applied to (..., 2) vectors."""
    out = np.asarray(steps).copy()
    for _ in range(k % 4):
        out = np.stack([-out[..., 1], out[..., 0]], axis=-1)
    if flip:
        out = out.copy()
        out[..., 0] = -out[..., 0]
    return out
