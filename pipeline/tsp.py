"""Orders through a few points: the TSP paths that TARE and guide_tsp plan at each decision.

Every decision of those planners orders at most a few dozen targets, so the order must be
bounded in time and deterministic: exact (Held-Karp) when small, else a nearest-neighbour
path improved by 2-opt and Or-opt moves under a move cap. The expert's tours over hundreds
of viewpoints are `pipeline.coverage`'s (python-tsp's Lin-Kernighan).
"""

from __future__ import annotations

import numpy as np


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


def path_length(distance: np.ndarray, order: list[int]) -> float:
    return float(sum(distance[a, b] for a, b in zip(order[:-1], order[1:])))


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


def _nearest_neighbour(distance: np.ndarray, end: int) -> list[int]:
    n = len(distance)
    left = np.ones(n, dtype=bool)
    left[[0, end]] = False
    order = [0]
    while left.any():
        candidates = np.nonzero(left)[0]
        nxt = int(candidates[np.argmin(distance[order[-1], candidates])])
        order.append(nxt)
        left[nxt] = False
    order.append(end)
    return order


def _improve(distance: np.ndarray, order: list[int], max_moves: int) -> list[int]:
    """Best-improvement 2-opt and Or-opt (segments of 1-3 points, either way round) on a
    path whose first and last points stay fixed."""
    p = np.array(order, dtype=np.int64)
    n = len(p)
    eps = 1e-9
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
