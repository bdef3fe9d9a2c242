"""Trajectory figures in the style of the GUIDE paper: the belief over the ground truth,
the lattice graph, the frontiers and the robot's path, as still frames, GIFs and panels.

Images are RGB uint8 arrays, row 0 at the top: grid cell (col, row) covers the pixels
[col * scale, (col + 1) * scale) x [row * scale, (row + 1) * scale) below the title bar.
World metres map to cells as the simulator does: cell = start_cell + round(xy / cell_size).
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from pipeline.common.atomic import atomic_file
from pipeline.lattice.frontier import frontier_mask
from pipeline.lattice.graph import NODE_FREE, LatticeGraph
from pipeline.world.maps import GroundTruthMap
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN

Colour = tuple[int, int, int]
Point = tuple[float, float]

# ----------------------------------------------------------------------------- palette (RGB)
UNKNOWN_FREE_RGB: Colour = (214, 217, 223)  # unexplored space
UNKNOWN_WALL_RGB: Colour = (184, 188, 198)  # ground-truth walls seen through the fog
FREE_RGB: Colour = (255, 255, 255)
OCCUPIED_RGB: Colour = (38, 44, 56)
FRONTIER_RGB: Colour = (235, 40, 60)
EDGE_RGB: Colour = (176, 196, 226)
NODE_RGB: Colour = (92, 120, 170)
UTILITY_RGB: Colour = (255, 160, 0)
START_RGB: Colour = (20, 170, 80)
ROBOT_RGB: Colour = (255, 230, 0)
OUTLINE_RGB: Colour = (20, 20, 20)
DOOR_RGB: Colour = (0, 190, 230)  # a door node the planner drove through (off the lattice)
FALLBACK_RGB: Colour = (230, 0, 200)  # a waypoint of the nearest-frontier fallback (the planner's rule found nothing)
HEADER_BG_RGB: Colour = (24, 34, 64)
HEADER_TEXT_RGB: Colour = (240, 242, 246)
HEADER_DIM_RGB: Colour = (170, 178, 192)
PANEL_GAP_RGB: Colour = (255, 255, 255)
# Path colour from start to end: teal -> blue -> violet -> magenta.
PATH_STOPS: tuple[Colour, ...] = ((0, 170, 170), (30, 100, 235), (130, 50, 210), (215, 0, 150))

FONT = cv2.FONT_HERSHEY_SIMPLEX
_SHIFT = 3  # sub-pixel bits for cv2 drawing
_ONE = 1 << _SHIFT


# ----------------------------------------------------------------------------- geometry
def world_to_cells(points: Sequence[Point] | np.ndarray, ground_truth: GroundTruthMap) -> np.ndarray:
    """World metres (x, y) -> grid cells (col, row), shape (n, 2) int64."""
    xy = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    return np.round(xy / ground_truth.cell_size).astype(np.int64) + np.asarray(ground_truth.start_cell, np.int64)


def _cell_centres_fixed(cells: np.ndarray, scale: int) -> np.ndarray:
    """Cell (col, row) -> pixel centre in cv2 fixed point (`_SHIFT` fractional bits), int32."""
    return np.round((np.asarray(cells, dtype=np.float64) + 0.5) * scale * _ONE).astype(np.int32).reshape(-1, 2)


def path_colours(n: int, stops: Sequence[Colour] = PATH_STOPS) -> np.ndarray:
    """`n` RGB colours graded along `stops` (first = start, last = end), shape (n, 3) uint8."""
    stops_arr = np.asarray(stops, dtype=np.float64)
    if n <= 0:
        return np.zeros((0, 3), dtype=np.uint8)
    t = np.linspace(0.0, 1.0, n) if n > 1 else np.zeros(1)
    knots = np.linspace(0.0, 1.0, len(stops_arr))
    out = np.stack([np.interp(t, knots, stops_arr[:, k]) for k in range(3)], axis=1)
    return np.round(out).astype(np.uint8)


def auto_scale(shape: tuple[int, int], target_px: int = 800, max_scale: int = 8) -> int:
    """The integer pixels-per-cell that makes the larger side of a grid about `target_px`."""
    return int(np.clip(target_px // max(1, max(shape)), 1, max_scale))


# ----------------------------------------------------------------------------- text and header
def _fit_text(text: str, width: int, font_scale: float, min_scale: float = 0.32) -> tuple[str, float]:
    """Shrink the font (then cut the text) until it fits in `width` pixels."""
    scale = font_scale
    while scale > min_scale and cv2.getTextSize(text, FONT, scale, 1)[0][0] > width:
        scale = round(scale - 0.02, 3)
    while len(text) > 1 and cv2.getTextSize(text, FONT, scale, 1)[0][0] > width:
        text = text[:-2] + "~"
    return text, scale


MARK_ITEMS = {"door": ("diamond", "door node", DOOR_RGB), "fallback": ("ring", "fallback", FALLBACK_RGB)}


def _legend_items(
    graph_shown: bool, belief_shown: bool = True, marks: Sequence[str] = ()
) -> list[tuple[str, str, Colour]]:
    items = [("box", "free", FREE_RGB), ("box", "wall", OCCUPIED_RGB)]
    if belief_shown:
        items += [
            ("box", "unexplored", UNKNOWN_FREE_RGB),
            ("box", "hidden wall", UNKNOWN_WALL_RGB),
            ("box", "frontier", FRONTIER_RGB),
        ]
    if graph_shown:
        items += [("dot", "node", NODE_RGB), ("dot", "utility>0", UTILITY_RGB)]
    items += [
        ("path", "path start>end", PATH_STOPS[0]),
        ("start", "start", START_RGB),
        ("robot", "robot" if belief_shown else "end", ROBOT_RGB),
    ]
    return items + [MARK_ITEMS[mark] for mark in marks]


def _legend_layout(items, width: int, font_scale: float, pad: int) -> list[list[tuple[int, tuple]]]:
    """Legend items flowed into rows: a list of rows of (x, item)."""
    swatch = 14
    rows: list[list[tuple[int, tuple]]] = [[]]
    x = pad
    for item in items:
        text_w = cv2.getTextSize(item[1], FONT, font_scale, 1)[0][0]
        w = swatch + 4 + text_w
        if rows[-1] and x + w > width - pad:
            rows.append([])
            x = pad
        rows[-1].append((x, item))
        x += w + 12
    return rows


def _draw_swatch(img: np.ndarray, kind: str, x: int, cy: int, colour: Colour) -> None:
    s = 14
    y0 = cy - s // 2
    if kind == "box":
        cv2.rectangle(img, (x, y0), (x + s - 1, y0 + s - 1), colour, -1)
        cv2.rectangle(img, (x, y0), (x + s - 1, y0 + s - 1), HEADER_DIM_RGB, 1)
    elif kind == "dot":
        cv2.circle(img, (x + s // 2, cy), 4, colour, -1, cv2.LINE_AA)
    elif kind == "path":
        cols = path_colours(s)
        for i in range(s - 1):
            cv2.line(img, (x + i, cy), (x + i + 1, cy), tuple(int(c) for c in cols[i]), 3)
    elif kind == "start":
        cv2.rectangle(img, (x + 2, y0 + 2), (x + s - 3, y0 + s - 3), colour, -1)
        cv2.rectangle(img, (x + 2, y0 + 2), (x + s - 3, y0 + s - 3), (255, 255, 255), 1)
    elif kind == "robot":
        cv2.circle(img, (x + s // 2, cy), 6, OUTLINE_RGB, -1, cv2.LINE_AA)
        cv2.circle(img, (x + s // 2, cy), 4, colour, -1, cv2.LINE_AA)
    elif kind == "diamond":
        _draw_diamond(img, (x + s // 2, cy), 5, colour, shift=0)
    elif kind == "ring":
        cv2.circle(img, (x + s // 2, cy), 5, colour, 2, cv2.LINE_AA)


def _draw_diamond(img: np.ndarray, centre: tuple[int, int], radius: float, colour: Colour, shift: int = _SHIFT) -> None:
    cx, cy = centre
    r = int(round(radius * (1 << shift)))
    pts = np.array([[cx, cy - r], [cx + r, cy], [cx, cy + r], [cx - r, cy]], dtype=np.int32)
    cv2.fillConvexPoly(img, pts, OUTLINE_RGB, cv2.LINE_AA, shift)
    inner = int(round(r * 0.7))
    pts = np.array([[cx, cy - inner], [cx + inner, cy], [cx, cy + inner], [cx - inner, cy]], dtype=np.int32)
    cv2.fillConvexPoly(img, pts, colour, cv2.LINE_AA, shift)


def _draw_marks(img: np.ndarray, doors: np.ndarray, fallbacks: np.ndarray, scale: int) -> None:
    """Door nodes as diamonds, fallback waypoints as rings, over the path."""
    size = max(3.0, 2.2 * scale)
    for c in _cell_centres_fixed(doors, scale) if len(doors) else ():
        _draw_diamond(img, (int(c[0]), int(c[1])), size, DOOR_RGB)
    for c in _cell_centres_fixed(fallbacks, scale) if len(fallbacks) else ():
        cv2.circle(
            img,
            (int(c[0]), int(c[1])),
            int(round(size * _ONE)),
            FALLBACK_RGB,
            max(1, scale // 2 + 1),
            cv2.LINE_AA,
            _SHIFT,
        )


def render_header(
    width: int,
    title: str = "",
    legend: bool = True,
    graph_shown: bool = True,
    belief_shown: bool = True,
    marks: Sequence[str] = (),
) -> np.ndarray | None:
    """The title bar: one line of `title` and, below it, the colour key. None when both are off.

    Its height depends only on `width`, `legend` and `graph_shown`, never on the title's
    text, so frames of one animation share one size.
    """
    if not title and not legend:
        return None
    base = 0.58 if width >= 1000 else 0.5 if width >= 600 else 0.42
    pad = 8
    title_h = 30 if width >= 1000 else 26 if width >= 600 else 22
    legend_scale = base * 0.85
    rows = _legend_layout(_legend_items(graph_shown, belief_shown, marks), width, legend_scale, pad) if legend else []
    row_h = 20
    height = title_h + len(rows) * row_h + (6 if rows else 0)
    img = np.empty((height, width, 3), dtype=np.uint8)
    img[:] = HEADER_BG_RGB
    if title:
        text, fs = _fit_text(title, width - 2 * pad, base)
        (_, th), _ = cv2.getTextSize(text, FONT, fs, 1)
        cv2.putText(img, text, (pad, (title_h + th) // 2 + 1), FONT, fs, HEADER_TEXT_RGB, 1, cv2.LINE_AA)
    for r, row in enumerate(rows):
        cy = title_h + r * row_h + row_h // 2
        for x, (kind, label, colour) in row:
            _draw_swatch(img, kind, x, cy, colour)
            (_, th), _ = cv2.getTextSize(label, FONT, legend_scale, 1)
            cv2.putText(img, label, (x + 18, cy + th // 2), FONT, legend_scale, HEADER_DIM_RGB, 1, cv2.LINE_AA)
    return img


# ----------------------------------------------------------------------------- layers
def _base_cells(ground_truth: GroundTruthMap, belief: np.ndarray) -> np.ndarray:
    """Per-cell RGB: belief where known, the ground truth faintly where unknown."""
    free_gt = ground_truth.free
    img = np.empty(belief.shape + (3,), dtype=np.uint8)
    img[:] = UNKNOWN_FREE_RGB
    img[(belief == UNKNOWN) & ~free_gt] = UNKNOWN_WALL_RGB
    img[belief == FREE] = FREE_RGB
    img[belief == OCCUPIED] = OCCUPIED_RGB
    return img


def _draw_graph(img: np.ndarray, graph: LatticeGraph, scale: int) -> None:
    centres = _cell_centres_fixed(graph.node_cells, scale)
    edges = graph.edges
    if len(edges):
        lines = [np.stack([centres[a], centres[b]])[:, None, :] for a, b in edges]
        cv2.polylines(img, lines, False, EDGE_RGB, 1, cv2.LINE_AA, _SHIFT)
    free = np.nonzero(graph.node_state == NODE_FREE)[0]
    r = max(1, scale) * _ONE
    for n in free:
        cv2.circle(img, tuple(int(v) for v in centres[n]), r, NODE_RGB, -1, cv2.LINE_AA, _SHIFT)
    useful = free[graph.utility[free] > 0]
    ru = int(round(max(2.0, 1.8 * scale) * _ONE))
    for n in useful:
        c = tuple(int(v) for v in centres[n])
        cv2.circle(img, c, ru + _ONE, OUTLINE_RGB, -1, cv2.LINE_AA, _SHIFT)
        cv2.circle(img, c, ru, UTILITY_RGB, -1, cv2.LINE_AA, _SHIFT)


def _draw_path(img: np.ndarray, cells: np.ndarray, scale: int, thickness: int) -> None:
    if len(cells) < 2:
        return
    pts = _cell_centres_fixed(cells, scale)
    colours = path_colours(len(pts) - 1)
    # A thin white casing keeps the path readable over walls and graph edges.
    cv2.polylines(img, [pts[:, None, :]], False, (255, 255, 255), thickness + 2, cv2.LINE_AA, _SHIFT)
    for i in range(len(pts) - 1):
        colour = tuple(int(c) for c in colours[i])
        cv2.line(
            img,
            tuple(int(v) for v in pts[i]),
            tuple(int(v) for v in pts[i + 1]),
            colour,
            thickness,
            cv2.LINE_AA,
            _SHIFT,
        )


def _draw_markers(img: np.ndarray, start_cell: np.ndarray, robot_cell: np.ndarray | None, scale: int) -> None:
    size = max(4.0, 3.0 * scale)
    cx, cy = (np.asarray(start_cell, dtype=np.float64) + 0.5) * scale
    p0 = (int(round((cx - size) * _ONE)), int(round((cy - size) * _ONE)))
    p1 = (int(round((cx + size) * _ONE)), int(round((cy + size) * _ONE)))
    cv2.rectangle(img, p0, p1, START_RGB, -1, cv2.LINE_AA, _SHIFT)
    cv2.rectangle(img, p0, p1, (255, 255, 255), 1, cv2.LINE_AA, _SHIFT)
    if robot_cell is not None:
        c = tuple(int(v) for v in _cell_centres_fixed(robot_cell, scale)[0])
        r = max(4.0, 2.6 * scale)
        cv2.circle(img, c, int(round((r + 1.5) * _ONE)), OUTLINE_RGB, -1, cv2.LINE_AA, _SHIFT)
        cv2.circle(img, c, int(round(r * _ONE)), ROBOT_RGB, -1, cv2.LINE_AA, _SHIFT)


# ----------------------------------------------------------------------------- frames
def render_frame(
    ground_truth: GroundTruthMap,
    belief: np.ndarray,
    trajectory: Sequence[Point],
    graph: "LatticeGraph | None" = None,
    scale: int = 2,
    title: str = "",
    *,
    frontier: np.ndarray | None = None,
    legend: bool = True,
    robot: Point | None = None,
    path_thickness: int | None = None,
    y_up: bool = False,
    doors: Sequence[Point] = (),
    fallbacks: Sequence[Point] = (),
) -> np.ndarray:
    """One figure: belief over the faint ground truth, frontiers, graph, path, markers, title bar.

    `doors` and `fallbacks` (world points) are marked on the path: the door nodes it drove through
    and the waypoints of the nearest-frontier fallback (`pipeline.planners.whole_building`).

    `y_up=True` draws row 0 at the bottom, as a ROS map's image shows it (its loader turns
    the image so that rows grow with y).

    `belief` is the uint8 FREE/OCCUPIED/UNKNOWN grid; `trajectory` the world waypoints from
    the start (0, 0). Frontier cells come from `frontier` when given, else from
    `graph.frontier`, else from `frontier_mask(belief)`. `robot` defaults to the last
    waypoint. Returns an RGB uint8 image of (header + rows * scale, cols * scale, 3).
    """
    belief = np.asarray(belief)
    if belief.shape != ground_truth.shape:
        raise ValueError(f"belief of shape {belief.shape} does not match the map's {ground_truth.shape}")
    scale = int(scale)
    if scale < 1:
        raise ValueError(f"scale must be a positive integer, got {scale}")
    cells = _base_cells(ground_truth, belief)
    if frontier is None:
        if graph is not None and graph.frontier.shape == belief.shape:
            frontier = graph.frontier
        else:
            frontier = frontier_mask(belief)
    cells[np.asarray(frontier, dtype=bool)] = FRONTIER_RGB
    img = np.ascontiguousarray(np.repeat(np.repeat(cells, scale, axis=0), scale, axis=1))
    if graph is not None:
        _draw_graph(img, graph, scale)
    traj = list(trajectory) if trajectory is not None else []
    path_cells = world_to_cells(traj, ground_truth) if traj else np.zeros((0, 2), np.int64)
    thickness = path_thickness if path_thickness is not None else max(2, int(round(scale * 1.2)))
    _draw_path(img, path_cells, scale, thickness)
    marks = [name for name, points in (("door", doors), ("fallback", fallbacks)) if len(points)]
    if marks:
        _draw_marks(
            img,
            world_to_cells(list(doors), ground_truth) if len(doors) else np.zeros((0, 2), np.int64),
            world_to_cells(list(fallbacks), ground_truth) if len(fallbacks) else np.zeros((0, 2), np.int64),
            scale,
        )
    if robot is not None:
        robot_cell = world_to_cells([robot], ground_truth)[0]
    else:
        robot_cell = path_cells[-1] if len(path_cells) else None
    _draw_markers(img, np.asarray(ground_truth.start_cell), robot_cell, scale)
    if y_up:
        img = np.ascontiguousarray(img[::-1])
    header = render_header(img.shape[1], title, legend, graph_shown=graph is not None, marks=marks)
    return img if header is None else np.concatenate([header, img], axis=0)


def episode_title(
    map_name: str,
    planner: str,
    distance_m: float,
    steps: int,
    explored: float | None = None,
    complete: bool | None = None,
) -> str:
    """The title bar's text: map | planner | distance | step [| explored] [| status]."""
    parts = [f"map {map_name}", planner or "?", f"{distance_m:.1f} m", f"step {steps}"]
    if explored is not None:
        parts.append(f"{100.0 * explored:.0f}% explored")
    if complete is not None:
        parts.append("complete" if complete else "incomplete")
    return "  |  ".join(parts)


# ----------------------------------------------------------------------------- files
def save_png(image: np.ndarray, path: str | Path) -> Path:
    """Write an RGB image as PNG (cv2 wants BGR), atomically; creates the folder. Returns the path."""
    path = Path(path)
    image = np.asarray(image)
    bgr = cv2.cvtColor(image, cv2.COLOR_RGB2BGR) if image.ndim == 3 else image
    with atomic_file(path) as tmp:
        if not cv2.imwrite(str(tmp), bgr):
            raise OSError(f"could not write {path}")
    return path


def save_gif(frames: Sequence[np.ndarray], path: str | Path, fps: float = 8, hold_last_s: float = 2.0) -> Path:
    """An animated GIF of RGB frames (one shared palette, loops forever, last frame held)."""
    from PIL import Image

    if not frames:
        raise ValueError("no frames to write")
    path = Path(path)
    images = [Image.fromarray(np.ascontiguousarray(f, dtype=np.uint8), "RGB") for f in frames]
    # One palette for all frames (from the first, middle and last) so colours do not flicker.
    picks = sorted({0, len(images) // 2, len(images) - 1})
    sample = np.concatenate([np.asarray(frames[i], dtype=np.uint8) for i in picks], axis=0)
    palette = Image.fromarray(sample, "RGB").quantize(colors=256, method=Image.Quantize.MEDIANCUT)
    quantised = [im.quantize(palette=palette, dither=Image.Dither.NONE) for im in images]
    frame_ms = int(round(1000.0 / max(fps, 0.1)))
    durations = [frame_ms] * len(quantised)
    durations[-1] = max(frame_ms, int(round(hold_last_s * 1000)))
    with atomic_file(path) as tmp:
        quantised[0].save(
            tmp,  # the same suffix as `path`, so Pillow picks the same format
            save_all=True,
            append_images=quantised[1:],
            duration=durations,
            loop=0,
            disposal=1,
            optimize=True,  # drops unused palette entries: several times smaller files
        )
    return path


# ----------------------------------------------------------------------------- recorder


# ----------------------------------------------------------------------------- reports
