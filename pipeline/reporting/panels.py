"""Finished episodes as figures: the final frame, the whole-building marks, the trust strip, and
planners side by side on one map.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from pipeline.lattice.frontier import frontier_mask
from pipeline.lattice.graph import LatticeGraph
from pipeline.reporting.render import (
    FONT,
    PANEL_GAP_RGB,
    Point,
    auto_scale,
    episode_title,
    render_frame,
    render_header,
    save_png,
)
from pipeline.world.maps import GroundTruthMap
from pipeline.world.sensor import FREE, OCCUPIED
from pipeline.world.simulator import EpisodeResult


def render_final(
    result: EpisodeResult,
    ground_truth: GroundTruthMap,
    belief: np.ndarray,
    graph: "LatticeGraph | None" = None,
    scale: int | None = None,
    path: str | Path | None = None,
    legend: bool = True,
    y_up: bool = False,
) -> np.ndarray:
    """The final figure of an episode (written to `path` as PNG when given).

    `scale=None` picks one that makes the figure about 800 px wide; `y_up` as in `render_frame`.
    """
    scale = auto_scale(ground_truth.shape) if scale is None else scale
    title = episode_title(
        result.map_name, result.planner, result.distance_m, result.steps, result.explored_ratio, result.complete
    )
    min_unknown = graph.spec.frontier_min_unknown_neighbours if graph is not None else 2
    doors, fallbacks = whole_building_marks(result, graph.spec.node_resolution if graph is not None else None)
    image = render_frame(
        ground_truth,
        belief,
        result.trajectory,
        graph,
        scale,
        title,
        frontier=frontier_mask(np.asarray(belief), min_unknown),
        legend=legend,
        y_up=y_up,
        doors=doors,
        fallbacks=fallbacks,
    )
    trust = [t for t in result.waypoint_trust if t is not None]
    if trust:  # a predicting planner's trust in its predictions, along the episode
        image = np.vstack([image, trust_strip(result.distances[-len(trust) :], trust, image.shape[1])])
    if path is not None:
        save_png(image, path)
    return image


def whole_building_marks(result: EpisodeResult, node_resolution: float | None) -> tuple[list[Point], list[Point]]:
    """(door nodes, fallback waypoints) of an episode's trajectory: the rows its fallback sent the
    robot to, and the other rows off the lattice (`node_resolution` metres; none when unknown)."""
    marked = result.waypoint_fallback if len(result.waypoint_fallback) == len(result.trajectory) else []
    fallbacks = [p for p, mark in zip(result.trajectory, marked) if mark]
    if node_resolution is None:
        return [], fallbacks
    d = node_resolution
    off = [
        p
        for k, p in enumerate(result.trajectory)
        if not (marked and marked[k]) and any(abs(round(v / d) * d - v) > 1e-3 for v in p)
    ]
    return off, fallbacks


TRUST_STRIP_HEIGHT = 90


TRUST_LINE_RGB = (40, 120, 200)


def trust_strip(distances: Sequence[float], trust: Sequence[float], width: int) -> np.ndarray:
    """A strip under an episode's figure: the planner's prediction trust (0-1) against the
    distance travelled, so a reader sees where the predictions stopped being believed."""
    strip = np.full((TRUST_STRIP_HEIGHT, width, 3), 255, dtype=np.uint8)
    left, right, top, bottom = 8, width - 8, 24, TRUST_STRIP_HEIGHT - 10
    d = np.asarray(distances, dtype=np.float64)
    t = np.clip(np.asarray(trust, dtype=np.float64), 0.0, 1.0)
    span = max(d[-1] - d[0], 1e-9) if len(d) else 1.0
    xs = left + (d - (d[0] if len(d) else 0.0)) / span * (right - left)
    ys = bottom - t * (bottom - top)
    for level in (0.0, 1.0):
        y = int(round(bottom - level * (bottom - top)))
        cv2.line(strip, (left, y), (right, y), (210, 210, 210), 1)
    points = np.stack([xs, ys], axis=1).round().astype(np.int32).reshape(-1, 1, 2)
    cv2.polylines(strip, [points], False, TRUST_LINE_RGB, 2, cv2.LINE_AA)
    text = f"prediction trust (0-1) against distance: {t[-1]:.2f} at the end, {t.min():.2f} lowest, {t.mean():.2f} mean"
    cv2.putText(strip, text, (left, 16), FONT, 0.45, (60, 60, 60), 1, cv2.LINE_AA)
    return strip


def _ground_truth_belief(ground_truth: GroundTruthMap) -> np.ndarray:
    return np.where(ground_truth.free, FREE, OCCUPIED).astype(np.uint8)


def render_comparison(
    ground_truth: GroundTruthMap, results: Sequence[tuple], scale: int | None = None, title: str = "", gap: int = 6
) -> np.ndarray:
    """Several planners' paths on the same map, one panel each, in a row.

    `results` holds (label, trajectory, distance_m) or (label, trajectory, distance_m,
    belief): without a belief (or with None) a panel shows the whole ground truth as known.
    An overall title bar (`title`, else the map's name, plus the colour key) sits above
    the panels; the shortest distance is marked. `scale=None` makes the row ~1500 px wide.
    """
    if not results:
        raise ValueError("nothing to compare")
    if scale is None:
        scale = auto_scale(ground_truth.shape, target_px=max(400, 1500 // len(results)))
    distances = [float(entry[2]) for entry in results]
    best = min(distances)
    panels = []
    any_belief = False
    for entry, distance in zip(results, distances):
        label, trajectory = entry[0], entry[1]
        belief = entry[3] if len(entry) > 3 else None
        any_belief |= belief is not None
        if belief is None:
            belief = _ground_truth_belief(ground_truth)
        panel_title = f"{label}  |  {distance:.1f} m"
        if len(results) > 1 and distance == best:
            panel_title += "  (shortest)"
        panels.append(render_frame(ground_truth, belief, trajectory, None, scale, panel_title, legend=False))
    height = max(p.shape[0] for p in panels)
    width = sum(p.shape[1] for p in panels) + gap * (len(panels) + 1)
    canvas = np.empty((height + 2 * gap, width, 3), dtype=np.uint8)
    canvas[:] = PANEL_GAP_RGB
    x = gap
    for p in panels:
        canvas[gap : gap + p.shape[0], x : x + p.shape[1]] = p
        x += p.shape[1] + gap
    header = render_header(width, title or f"map {ground_truth.name}", True, graph_shown=False, belief_shown=any_belief)
    return np.concatenate([header, canvas], axis=0)
