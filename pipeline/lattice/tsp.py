"""Routes through points: every TSP path the project plans, and their 2-opt / Or-opt polish.

Both start from one nearest-neighbour construction and measure paths with one `path_length`.
Two solvers, for two sizes of problem:

- `tsp_path`: the orders TARE and guide_tsp plan at every decision, through at most a few
  dozen targets, so bounded in time and deterministic: exact (Held-Karp) when small, else a
  nearest-neighbour path improved by 2-opt and Or-opt moves under a move cap.
- `open_tsp_order`: the ground-truth coverage tours (`optimal`, `expert`) through hundreds of
  viewpoints: python-tsp's exact dynamic programming when small, else its Lin-Kernighan,
  then 2-opt and Or-opt on the open path.
"""

from __future__ import annotations

from typing import Literal, Sequence

import numpy as np
from python_tsp.exact import solve_tsp_dynamic_programming
from python_tsp.heuristics import solve_tsp_lin_kernighan

EXACT_TSP_MAX_NODES = 10  # open_tsp_order's exact limit: python-tsp's DP doubles its time with every node


def tsp_path(distance: np.ndarray, end: int | None = None, exact_max: int = 10, max_moves: int = 200) -> list[int]:
    """An order of the points 0..n-1 that starts at 0 (and ends at `end` if given) with a
    short total length along `distance` (symmetric, finite).

    Exact (Held-Karp) when at most `exact_max` points follow the start; otherwise nearest
    neighbour construction improved by 2-opt and Or-opt, at most `max_moves` moves.
    """
    distance = np.asarray(distance, dtype=np.float64)
    n = len(distance)
    if n <= 2:
        return list(range(n))
    if end is None:
        # Open end: append a dummy point at distance 0 from all and make it the fixed end.
        ext = np.zeros((n + 1, n + 1))
        ext[:n, :n] = distance
        order = tsp_path(ext, end=n, exact_max=exact_max, max_moves=max_moves)
        return [p for p in order if p != n]
    if end == 0:
        raise ValueError("the end of a TSP path must differ from its start")
    if n - 1 <= exact_max:
        return _held_karp(distance, end)
    order = _nearest_neighbour(distance, end)
    return _improve(distance, order, max_moves)


def path_length(distance: np.ndarray, order: Sequence[int] | np.ndarray) -> float:
    """The length of the path through `order` along `distance`, its legs added one by one in
    order (a sequential sum, so equal paths have equal lengths bit for bit)."""
    order = np.asarray(order, dtype=np.int64)
    if len(order) < 2:
        return 0.0
    return float(np.add.accumulate(distance[order[:-1], order[1:]])[-1])


def _held_karp(distance: np.ndarray, end: int) -> list[int]:
    """Exact shortest path from 0 through every point to `end` (dynamic programming)."""
    n = len(distance)
    m = n - 1  # points 1..n-1 as bits 0..m-1
    w = distance[1:, 1:]
    full = (1 << m) - 1
    masks = np.arange(1 << m)
    bits = (masks[:, None] >> np.arange(m)[None, :]) & 1
    popcount = bits.sum(axis=1)
    cost = np.full((1 << m, m), np.inf)
    parent = np.full((1 << m, m), -1, dtype=np.int64)
    single = 1 << np.arange(m)
    cost[single, np.arange(m)] = distance[0, 1:]
    for size in range(2, m + 1):
        layer = masks[popcount == size]
        inside = bits[layer].astype(bool)  # (C, k)
        prev = layer[:, None] ^ single[None, :]  # (C, k): the set before adding k
        prev = np.where(inside, prev, 0)
        # via[c, k, j] = cost[prev[c, k], j] + w[j, k]
        via = cost[prev] + w.T[None, :, :]
        best = via.argmin(axis=2)
        value = np.take_along_axis(via, best[..., None], axis=2)[..., 0]
        cost[layer] = np.where(inside, value, np.inf)
        parent[layer] = np.where(inside, best, -1)
    order = []
    mask, k = full, end - 1
    while k >= 0:
        order.append(k + 1)
        k, mask = int(parent[mask, k]), mask ^ (1 << k)
    order.append(0)
    return order[::-1]


def _nearest_neighbour(distance: np.ndarray, end: int | None = None) -> list[int]:
    """The path from 0 that always goes on to the nearest point not yet visited (the lowest index
    among equals), through every point, to `end` last when given (else wherever it ends)."""
    n = len(distance)
    left = np.ones(n, dtype=bool)
    left[0] = False
    if end is not None:
        left[end] = False
    order = [0]
    while left.any():
        candidates = np.nonzero(left)[0]
        nxt = int(candidates[np.argmin(distance[order[-1], candidates])])
        order.append(nxt)
        left[nxt] = False
    if end is not None:
        order.append(end)
    return order


def _improve(distance: np.ndarray, order: list[int], max_moves: int) -> list[int]:
    """Best-improvement 2-opt and Or-opt (segments of 1-3 points, either way round) on a
    path whose first and last points stay fixed."""
    p = np.array(order, dtype=np.int64)
    n = len(p)
    eps = 1e-9
    best_move: tuple[Literal["2opt"], int, int, bool] | tuple[Literal["or"], int, int, bool, int] | None
    for _ in range(max_moves):
        best_gain, best_move = eps, None
        # 2-opt: reverse p[i..j], 1 <= i < j <= n-2.
        idx = np.arange(1, n - 1)
        a, b = p[idx - 1], p[idx]
        c, d = p[idx], p[idx + 1]
        gain = (distance[a, b][:, None] + distance[c, d][None, :]) - (
            distance[a[:, None], c[None, :]] + distance[b[:, None], d[None, :]]
        )
        gain = np.where(idx[:, None] < idx[None, :], gain, -np.inf)
        flat = int(np.argmax(gain))
        if gain.flat[flat] > best_gain:
            best_gain = float(gain.flat[flat])
            best_move = ("2opt", int(idx[flat // len(idx)]), int(idx[flat % len(idx)]), False)
        # Or-opt: move p[i..i+l-1] between p[q] and p[q+1] (q not touching the segment).
        q = np.arange(0, n - 1)
        for length in (1, 2, 3):
            starts = np.arange(1, n - length)  # segment within 1..n-2
            if starts.size == 0:
                break
            first, last = p[starts], p[starts + length - 1]
            before, after = p[starts - 1], p[starts + length]
            removal = distance[before, first] + distance[last, after] - distance[before, after]
            u, v = p[q], p[q + 1]
            base = distance[u, v][None, :]
            forward = distance[u[None, :], first[:, None]] + distance[last[:, None], v[None, :]] - base
            backward = distance[u[None, :], last[:, None]] + distance[first[:, None], v[None, :]] - base
            ok = (q[None, :] < starts[:, None] - 1) | (q[None, :] > starts[:, None] + length - 1)
            for reverse, insert in ((False, forward), (True, backward)):
                g = np.where(ok, removal[:, None] - insert, -np.inf)
                flat = int(np.argmax(g))
                if g.flat[flat] > best_gain:
                    best_gain = float(g.flat[flat])
                    best_move = ("or", int(starts[flat // len(q)]), int(q[flat % len(q)]), reverse, length)
        if best_move is None:
            break
        if best_move[0] == "2opt":
            _, i, j, _ = best_move
            p[i : j + 1] = p[i : j + 1][::-1].copy()
        else:
            _, i, qq, reverse, length = best_move
            segment = p[i : i + length].copy()
            if reverse:
                segment = segment[::-1]
            rest = np.concatenate([p[:i], p[i + length :]])
            # Edge (p[qq], p[qq+1]) in the old path; find p[qq] in the rest.
            pos = int(np.nonzero(rest == p[qq])[0][0])
            p = np.concatenate([rest[: pos + 1], segment, rest[pos + 1 :]])
    return [int(x) for x in p]


# --------------------------------------------------------------------------- large open tours
def _two_opt_open(dist: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Best-improvement 2-opt on an open path with a fixed first node (symmetric distances)."""
    m = len(p)
    if m < 3:
        return p
    while True:
        prev, first, last = p[:-1], p[1:], p[1:]  # p[i-1], p[i] and p[j] for i, j = 1..m-1
        nxt = np.append(p[2:], -1)  # p[j+1]; -1 when j is the end
        has_next = nxt >= 0
        nxt_safe = np.where(has_next, nxt, 0)
        before = dist[prev, first][:, None] + np.where(has_next, dist[last, nxt_safe], 0.0)[None, :]
        after = dist[prev[:, None], last[None, :]] + np.where(
            has_next[None, :], dist[first[:, None], nxt_safe[None, :]], 0.0
        )
        delta = after - before  # reversing p[i..j]
        delta[np.tril_indices(m - 1)] = 0.0
        k = int(np.argmin(delta))
        if delta.flat[k] > -1e-7:
            return p
        i, j = (int(v) + 1 for v in np.unravel_index(k, delta.shape))
        p = np.concatenate([p[:i], p[i : j + 1][::-1], p[j + 1 :]])


def _or_opt_open(dist: np.ndarray, p: np.ndarray, max_segment: int = 3) -> np.ndarray:
    """Move a run of 1..max_segment nodes (maybe reversed) elsewhere in an open path."""
    base = path_length(dist, p)
    improved = True
    while improved:
        improved = False
        m = len(p)
        for s in range(1, max_segment + 1):
            for i in range(1, m - s + 1):
                seg = p[i : i + s]
                rest = np.concatenate([p[:i], p[i + s :]])
                after_a = np.append(rest[1:], -1)  # the node after each insertion point
                has_b = after_a >= 0
                b = np.where(has_b, after_a, 0)
                link = np.where(has_b, dist[rest, b], 0.0)
                fwd = dist[rest, seg[0]] + np.where(has_b, dist[seg[-1], b], 0.0) - link
                rev = dist[rest, seg[-1]] + np.where(has_b, dist[seg[0], b], 0.0) - link
                cost = path_length(dist, rest) + path_length(dist, seg) + np.minimum(fwd, rev)
                k = int(np.argmin(cost))
                if cost[k] < base - 1e-7:
                    piece = seg if fwd[k] <= rev[k] else seg[::-1]
                    p = np.concatenate([rest[: k + 1], piece, rest[k + 1 :]])
                    base = path_length(dist, p)
                    improved = True
                    break
            if improved:
                break
    return p


def open_tsp_order(
    dist: np.ndarray, exact_max_nodes: int = EXACT_TSP_MAX_NODES, x0: Sequence[int] | None = None
) -> np.ndarray:
    """Order of an open path through all nodes of `dist` from node 0, ending anywhere.

    Up to `exact_max_nodes` nodes: python-tsp's exact dynamic programming, with the return
    to node 0 made free (its column set to 0), so the best cycle is the best open path.
    Larger: python-tsp's Lin-Kernighan from a nearest-neighbour (or given) start, then
    2-opt and or-opt on the open path. Deterministic.
    """
    n = len(dist)
    if n <= 2:
        return np.arange(n)
    dist = np.asarray(dist, dtype=np.float64)
    if n <= exact_max_nodes:
        closed = dist.copy()
        closed[:, 0] = 0.0
        perm, _ = solve_tsp_dynamic_programming(closed)
        return np.asarray(perm, dtype=np.int64)
    if x0 is None:
        x0 = _nearest_neighbour(dist)
    # Lin-Kernighan gets a symmetric instance in whole millimetres: python-tsp 0.5's LK
    # tracks the tour length incrementally and, on float lengths, can take rounding noise
    # for an improvement and never stop (seen on 17-node instances, with the asymmetric
    # free-return matrix and with this one); with integers every accepted move is a real
    # gain, so it terminates. A dummy node n joins the start at cost 0 and every other node
    # at a constant `big` larger than any open path, so the best cycle is
    # start ... last -> dummy -> start: the best open path plus `big`.
    scaled = np.round(dist * 1000.0)
    big = float(scaled.max()) * n + 1.0
    closed = np.full((n + 1, n + 1), big)
    closed[:n, :n] = scaled
    closed[n, 0] = closed[0, n] = closed[n, n] = 0.0
    perm = [int(v) for v in solve_tsp_lin_kernighan(closed, x0=[int(v) for v in x0] + [n])[0]]
    # The cycle starts at 0; read the path away from the dummy's side.
    perm = [0] + perm[2:][::-1] if perm[1] == n else [v for v in perm if v != n]
    p = np.asarray(perm, dtype=np.int64)
    for _ in range(4):
        before = path_length(dist, p)
        p = _or_opt_open(dist, _two_opt_open(dist, p))
        if path_length(dist, p) >= before - 1e-7:
            break
    return p
