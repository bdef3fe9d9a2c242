"""Receding-horizon next-best-view planning (Bircher et al., ICRA 2016) on the node lattice.

Each decision grows a rapidly-exploring random tree in known free space, rooted at the
robot's lattice node, scores every branch by the unknown space its nodes would see, and
executes only the first edge of the best branch. The rest of that branch is kept and put
back into the next decision's tree (as Bircher does), so the plan is not lost between
decisions.

Adaptation to the lattice and the protocol:

- Tree vertices are lattice nodes and tree edges are exactly the lattice graph's valid
  edges (a node and one of its 5x5-window neighbours, the segment known free in either
  walk direction), so every executed step obeys the motion rule by construction.
- Sampling: a point uniform in the square of half-side `sample_radius_factor` x sensor
  range (2 x 20 m by default) around the robot, intersected with the bounding box of the
  known free cells. The nearest tree vertex (Euclidean) steers toward it by at most two
  lattice steps per axis (the direction is kept by scaling the offset so that its larger
  component is 2 steps, then rounding to the lattice); the new vertex is added when the
  edge is valid and the vertex is not yet in the tree. Samples come from the planner's
  `rng`, seeded in `reset`, so a run is reproducible.
- Gain G(n) of a vertex: the number of distinct unknown cells that a fan of the lidar's
  rays (every `ray_stride`-th of the 720 protocol rays, same range, same 4-connected walk)
  would see from it. A ray passes free and unknown cells and stops at a known occupied
  cell, the grid edge, or before its end cell, as the real sensor does. Because the fan is
  a subset of the real sensor's rays, a vertex the robot has sensed from has gain 0.
- Branch value as Bircher: Gain(n_k) = Gain(n_{k-1}) + G(n_k) exp(-lambda c(n_k)), with
  c the path length (metres) from the root along the tree. The default lambda = 2.5 /
  sensor range (0.125 /m at 20 m) weighs a view one sensor range away by exp(-2.5) ~ 0.08
  under any protocol: the unit-free product lambda x sensor range is what carries over.
- Defaults: tree_size N = 40 vertices (the robot's node included), at most
  `max_attempts_factor` x N samples per decision (a small known-free area may hold fewer
  than N lattice nodes), `gain_threshold` = 20 cells, gains from every 4th lidar ray.
- Fallback (not in the paper, which stops instead): when the best branch value is below
  `gain_threshold`, the local tree sees nothing worth the trip, and the planner takes one
  step along the shortest graph path to the nearest useful frontier node, exactly as
  `nearest_frontier` does. It returns [] only when no useful node is reachable, so an
  episode ends only when the map is explored or nothing reachable is left.
"""

from __future__ import annotations

import math
from typing import Annotated

import numpy as np
from pydantic import Strict

from pipeline.common.config import any_of, config_dataclass, flag, maybe, positive, real, satisfies, whole
from pipeline.lattice.graph import NODE_FREE, WINDOW_RADIUS
from pipeline.planners.config import option
from pipeline.planners.graph_planner import GraphPlanner, LatticePlannerConfig
from pipeline.planners.registry import register_planner
from pipeline.world.geometry import RayTable, ray_table
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import DEFAULT_ANGLES, FREE, OCCUPIED, UNKNOWN

WINDOW = 2 * WINDOW_RADIUS + 1
LAM_TIMES_RANGE = 2.5  # Bircher's lambda x sensor range: a view one range away counts exp(-2.5)


class ViewGain:
    """Vectorised view gain: distinct unknown cells a ray fan sees from many origins at once.

    The belief is padded by the sensor range with OCCUPIED cells, so a ray leaving the grid
    stops exactly where it would at the grid edge and no bounds checks are needed; each
    ray cell is then one flat offset from the origin's flat index. Every ray ends with at
    least one padding step (never reached), so each ray's stop is one `argmax`.
    """

    def __init__(self, shape: tuple[int, int], range_cells: float, ray_stride: int = 4, chunk: int = 32):
        if ray_stride < 1:
            raise ValueError(f"ray_stride must be >= 1, got {ray_stride}")
        self.shape = shape
        self.chunk = int(chunk)
        self.table: RayTable = ray_table(0, 0, range_cells, DEFAULT_ANGLES[::ray_stride])
        self.pad = int(np.abs(self.table.end_offsets).max()) + 1
        rows, cols = shape
        self.padded_shape = (rows + 2 * self.pad, cols + 2 * self.pad)
        pcols = self.padded_shape[1]
        n_rays = self.table.valid.shape[0]
        off = np.concatenate([self.table.offsets, np.zeros((n_rays, 1, 2), dtype=np.int64)], axis=1)
        self.flat_offsets = off[..., 1] * pcols + off[..., 0]
        self.invalid = ~np.concatenate([self.table.valid, np.zeros((n_rays, 1), dtype=bool)], axis=1)
        self.steps = np.arange(self.flat_offsets.shape[1])
        self.n_unique = len(self.table.unique_offsets)
        unique_index = np.concatenate([np.maximum(self.table.unique_index, 0), np.zeros((n_rays, 1), np.int64)], axis=1)
        # seen-matrix flat index of (origin k in a chunk, ray, step): k * n_unique + unique cell.
        self._seen_key = np.arange(self.chunk)[:, None, None] * self.n_unique + unique_index[None]
        self._padded = np.full(self.padded_shape, OCCUPIED, dtype=np.uint8)

    def load(self, belief: np.ndarray) -> None:
        """Copy the current belief into the padded working grid."""
        rows, cols = self.shape
        self._padded[self.pad : self.pad + rows, self.pad : self.pad + cols] = belief

    def gains(self, cells: np.ndarray) -> np.ndarray:
        """Gain of each origin cell (col, row) on the belief last passed to `load`."""
        cells = np.asarray(cells, dtype=np.int64).reshape(-1, 2)
        out = np.zeros(len(cells), dtype=np.int64)
        flat_grid = self._padded.reshape(-1)
        pcols = self.padded_shape[1]
        origin = (cells[:, 1] + self.pad) * pcols + cells[:, 0] + self.pad
        for start in range(0, len(cells), self.chunk):
            org = origin[start : start + self.chunk]
            n = len(org)
            values = flat_grid[org[:, None, None] + self.flat_offsets[None]]
            stop = np.argmax((values == OCCUPIED) | self.invalid[None], axis=2)
            seen_unknown = (self.steps < stop[..., None]) & (values == UNKNOWN)
            seen = np.zeros(n * self.n_unique, dtype=bool)
            seen[self._seen_key[:n][seen_unknown]] = True
            out[start : start + n] = seen.reshape(n, self.n_unique).sum(axis=1)
        return out


def view_gains(belief: np.ndarray, cells: np.ndarray, range_cells: float, ray_stride: int = 4) -> np.ndarray:
    """Convenience wrapper: NBVP gain of each cell (col, row) on `belief`."""
    gain = ViewGain(belief.shape, range_cells, ray_stride)
    gain.load(belief)
    return gain.gains(cells)


def _infinite(value: float) -> None:
    """ValueError unless `value` is +inf (a gain threshold that always falls back)."""
    if value != math.inf:
        raise ValueError(f"{value!r} is not inf")


@config_dataclass
class NBVPConfig(LatticePlannerConfig):
    description = (
        "Bircher 2016 receding-horizon NBVP: lattice RRT in known free space, first edge of the "
        "best-gain branch; nearest-frontier fallback when the local tree sees nothing"
    )

    tree_size: Annotated[int, whole(2, note="the robot's node and at least one more")] = option(
        40, "tree vertices N per decision, the robot's node included"
    )
    lam: Annotated[float | None, maybe(real(0.0), f"{LAM_TIMES_RANGE:g} / sensor range")] = option(
        None,
        f"lambda (1/m) discounting a view by its path length [default: {LAM_TIMES_RANGE:g} / sensor range, so a "
        "view one range away counts exp(-2.5) under any protocol]",
    )
    # Branch values are >= 0, so a negative threshold is 0 (never fall back); +inf always falls back.
    gain_threshold: Annotated[
        float,
        any_of(
            real(0.0),
            satisfies(_infinite, "inf", Annotated[float, Strict()]),
            description="a number >= 0 (inf = always the frontier fallback)",
        ),
    ] = option(20.0, "cells: a best branch worth less falls back to the nearest frontier (inf = always)")
    sample_radius_factor: Annotated[float, positive()] = option(
        2.0, "samples are drawn within this many sensor ranges of the robot"
    )
    ray_stride: Annotated[int, whole(1)] = option(4, "gains from every n-th of the lidar's 720 rays")
    max_attempts_factor: Annotated[int, whole(1)] = option(
        15, "at most this many x tree_size samples per decision (a small known area holds fewer nodes)"
    )
    reuse_best_branch: Annotated[bool, flag()] = option(
        True, "the rest of the executed branch seeds the next tree, as Bircher does"
    )


@register_planner("nbvp", NBVPConfig)
class NBVPPlanner(GraphPlanner):
    """Bircher's receding-horizon next-best-view planner: RRT in known free space, first edge
    of the branch with the most discounted unknown-volume gain; nearest frontier fallback."""

    description = NBVPConfig.description

    def __init__(self, config: NBVPConfig = NBVPConfig()):
        super().__init__(config)
        tree_size, lam, gain_threshold = config.tree_size, config.lam, config.gain_threshold
        sample_radius_factor, ray_stride = config.sample_radius_factor, config.ray_stride
        max_attempts_factor, reuse_best_branch = config.max_attempts_factor, config.reuse_best_branch
        self.tree_size = int(tree_size)
        self.lam_option = lam  # 1/m; None: LAM_TIMES_RANGE / the protocol's sensor range, set in reset()
        self.lam = 0.0 if lam is None else float(lam)
        self.gain_threshold = float(gain_threshold)
        self.sample_radius_factor = float(sample_radius_factor)
        self.ray_stride = int(ray_stride)
        self.max_attempts_factor = int(max_attempts_factor)
        self.reuse_best_branch = bool(reuse_best_branch)
        self._branch: list[int] = []
        self.last_decision: dict = {}

    # ----------------------------------------------------------------- episode setup
    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        super().reset(frame, protocol, seed)
        graph = self.graph
        assert graph is not None
        self.lam = LAM_TIMES_RANGE / protocol.sensor_range if self.lam_option is None else float(self.lam_option)
        self.view_gain = ViewGain(frame.shape, protocol.sensor_range_cells, self.ray_stride)
        # edge_of[node, window slot] = id of the candidate edge to that neighbour, -1 if none.
        self._edge_of = np.full((graph.node_count, WINDOW * WINDOW), -1, dtype=np.int64)
        a, b = graph.edge_nodes[:, 0], graph.edge_nodes[:, 1]
        d = graph.node_ij[b] - graph.node_ij[a]
        ids = np.arange(len(a))
        self._edge_of[a, self._slot(d[:, 0], d[:, 1])] = ids
        self._edge_of[b, self._slot(-d[:, 0], -d[:, 1])] = ids
        self._i0, self._j0 = int(graph.lattice_i[0]), int(graph.lattice_j[0])
        self._id_grid_shape = (len(graph.lattice_j), len(graph.lattice_i))
        self._branch = []
        self.last_decision = {}

    @staticmethod
    def _slot(di, dj):
        return (dj + WINDOW_RADIUS) * WINDOW + (di + WINDOW_RADIUS)

    def _edge_ok(self, a: int, b: int) -> bool:
        """True when a-b is a valid graph edge (known-free segment, 5x5 window)."""
        assert self.graph is not None
        di, dj = self.graph.node_ij[b] - self.graph.node_ij[a]
        if abs(di) > WINDOW_RADIUS or abs(dj) > WINDOW_RADIUS or (di == 0 and dj == 0):
            return False
        e = self._edge_of[a, self._slot(int(di), int(dj))]
        return bool(e >= 0 and self.graph.edge_valid[e])

    # ----------------------------------------------------------------- the tree
    def _sample_box(self, belief: np.ndarray, position: tuple[float, float]) -> tuple[float, float, float, float]:
        """World box (x0, x1, y0, y1) where samples are drawn."""
        assert self.graph is not None
        free = belief == FREE
        cols = np.nonzero(free.any(axis=0))[0]
        rows = np.nonzero(free.any(axis=1))[0]
        lo = self.graph.spec.cell_to_world(np.array([cols[0], rows[0]]))
        hi = self.graph.spec.cell_to_world(np.array([cols[-1], rows[-1]]))
        r = self.sample_radius_factor * self.protocol.sensor_range
        x0, x1 = max(lo[0], position[0] - r), min(hi[0], position[0] + r)
        y0, y1 = max(lo[1], position[1] - r), min(hi[1], position[1] + r)
        return x0, max(x0, x1), y0, max(y0, y1)

    def grow_tree(self, observation: Observation, root: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """RRT of lattice nodes in known free space: (nodes, parent index, path cost in metres).

        Index 0 is the root; a parent always comes before its children.
        """
        graph = self.graph
        assert graph is not None
        d = graph.spec.node_resolution
        n_max = self.tree_size
        nodes = [root]
        parent = [-1]
        cost = [0.0]
        tree_ij = [(int(graph.node_ij[root][0]), int(graph.node_ij[root][1]))]
        in_tree = {root}

        # Bircher: the rest of the previous best branch goes back into the new tree.
        if self.reuse_best_branch and self._branch and self._branch[0] == root:
            for node in self._branch[1:]:
                prev = nodes[-1]
                if len(nodes) >= n_max or node in in_tree:
                    break
                if graph.node_state[node] != NODE_FREE or not self._edge_ok(prev, node):
                    break
                nodes.append(node)
                parent.append(len(nodes) - 2)
                cost.append(cost[-1] + float(np.hypot(*(graph.node_world[node] - graph.node_world[prev]))))
                tree_ij.append((int(graph.node_ij[node][0]), int(graph.node_ij[node][1])))
                in_tree.add(node)
        self._branch = []

        # All samples of this decision at once (lattice units), from the seeded rng.
        x0, x1, y0, y1 = self._sample_box(observation.belief, observation.position)
        attempts = self.max_attempts_factor * n_max
        samples = self.rng.uniform(0.0, 1.0, size=(attempts, 2))
        samples[:, 0] = (x0 + samples[:, 0] * (x1 - x0)) / d
        samples[:, 1] = (y0 + samples[:, 1] * (y1 - y0)) / d

        # Each sample's nearest tree vertex is kept up to date, vectorised over the samples,
        # as vertices are added; a new vertex replaces it only when strictly nearer, as an
        # argmin over the tree would keep the earlier vertex on a tie.
        near = np.zeros(attempts, dtype=np.int64)
        near_d = np.full(attempts, np.inf)

        def add_to_nearest(k: int) -> None:
            diff = samples - tree_ij[k]
            d2 = diff[:, 0] ** 2 + diff[:, 1] ** 2
            closer = d2 < near_d
            near_d[closer] = d2[closer]
            near[closer] = k

        for k in range(len(nodes)):
            add_to_nearest(k)

        node_free = (graph.node_state == NODE_FREE).tolist()
        edge_valid = graph.edge_valid
        edge_of = self._edge_of
        rows, cols = self._id_grid_shape
        i0, j0 = self._i0, self._j0
        limit = float(WINDOW_RADIUS)
        for s_idx, (si, sj) in enumerate(samples.tolist()):
            if len(nodes) >= n_max:
                break
            p = int(near[s_idx])
            ni, nj = tree_ij[p]
            # Steer: keep the direction, at most WINDOW_RADIUS lattice steps per axis.
            di, dj = si - ni, sj - nj
            m = max(abs(di), abs(dj))
            if m > limit:
                di, dj = di * limit / m, dj * limit / m
            di, dj = round(di), round(dj)  # half to even, as numpy rounds
            ti, tj = ni + di, nj + dj
            if (di == 0 and dj == 0) or not (0 <= ti - i0 < cols and 0 <= tj - j0 < rows):
                continue
            target = (tj - j0) * cols + (ti - i0)
            if target in in_tree or not node_free[target]:
                continue
            edge = edge_of[nodes[p], self._slot(di, dj)]
            if edge < 0 or not edge_valid[edge]:
                continue
            nodes.append(target)
            parent.append(p)
            cost.append(cost[p] + d * float(np.hypot(di, dj)))
            tree_ij.append((ti, tj))
            in_tree.add(target)
            add_to_nearest(len(nodes) - 1)
        return np.array(nodes, dtype=np.int64), np.array(parent, dtype=np.int64), np.array(cost)

    def branch_values(self, gains: np.ndarray, parent: np.ndarray, cost: np.ndarray) -> np.ndarray:
        """Bircher's Gain(n_k) = Gain(n_{k-1}) + G(n_k) exp(-lambda c(n_k)); root value 0.

        Parents always come before their children in the tree arrays.
        """
        values = np.zeros(len(gains), dtype=np.float64)
        term = gains * np.exp(-self.lam * cost)
        for k in range(1, len(gains)):
            values[k] = values[parent[k]] + term[k]
        return values

    # ----------------------------------------------------------------- decisions
    def plan(self, observation: Observation) -> list[Waypoint]:
        graph = self.update_graph(observation)
        robot = self.robot_node(observation)
        nodes, parent, cost = self.grow_tree(observation, robot)
        if len(nodes) > 1:
            self.view_gain.load(observation.belief)
            gains = np.zeros(len(nodes), dtype=np.int64)
            gains[1:] = self.view_gain.gains(graph.node_cells[nodes[1:]])
            values = self.branch_values(gains, parent, cost)
            best = int(np.argmax(values[1:])) + 1
            self.last_decision = {"tree": nodes, "parent": parent, "gain": gains, "value": values, "best": best}
            if values[best] >= self.gain_threshold:
                branch = [best]
                while parent[branch[-1]] > 0:
                    branch.append(int(parent[branch[-1]]))
                branch.reverse()  # tree indices from the root's child to the best vertex
                self._branch = [int(nodes[k]) for k in branch]
                self.last_decision["mode"] = "nbv"
                return self.waypoints_along([robot, self._branch[0]])
        else:
            self.last_decision = {"tree": nodes, "parent": parent}
        self.last_decision["mode"] = "frontier"
        return self._nearest_frontier_step(robot)

    def _nearest_frontier_step(self, robot: int) -> list[Waypoint]:
        """Fallback: one step toward the nearest useful frontier node (as nearest_frontier)."""
        self._branch = []
        return self.nearest_useful_step(robot)
