"""Figures of one team episode: its robots' paths on its map and its animation (the team coverage
curves are `coverage_figure.team_coverage_figure`).

The paths figure draws the map as `render.render_frame` does (the belief the team built, over the
faint ground truth), then each robot's path in its own colour, its start as a square (nested
when robots share a start) and its last position as a dot. The animation is that figure at evenly
spaced team times, each frame drawn from the rows up to its time.
"""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from pipeline.reporting.render import (
    FONT,
    OUTLINE_RGB,
    auto_scale,
    render_frame,
    render_header,
    save_gif,
    save_png,
    world_to_cells,
)
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import Belief, Lidar
from pipeline.world.team import lattice_cell

# One colour per robot (RGB), one for each of the MAX_ROBOTS a team may have, distinct from the
# map's palette: blue, orange, green, red, violet, brown, pink, olive.
ROBOT_RGB: tuple[tuple[int, int, int], ...] = (
    (31, 119, 180),
    (255, 127, 14),
    (44, 160, 44),
    (214, 39, 40),
    (148, 103, 189),
    (140, 86, 75),
    (227, 119, 194),
    (188, 189, 34),
)
KEY_HEIGHT = 24  # the strip under the title that names each robot's colour


def team_belief(
    ground_truth: GroundTruthMap, rows: Sequence[tuple[float, int, float, float]], protocol: Protocol
) -> np.ndarray:
    """The union belief a team's rows build: a scan at every row's position (the starts included)."""
    belief = Belief(ground_truth.shape)
    lidar = Lidar(ground_truth.free, protocol.sensor_range_cells)
    for _, _, x, y in rows:
        belief.apply(lidar.scan(lattice_cell(ground_truth, protocol, (x, y))))
    return belief.grid


def robot_paths(rows: Sequence[tuple[float, int, float, float]]) -> list[list[tuple[float, float]]]:
    """Each robot's waypoints (metres) in order, its start first."""
    robots = 1 + max(int(robot) for _, robot, _, _ in rows)
    paths: list[list[tuple[float, float]]] = [[] for _ in range(robots)]
    for _, robot, x, y in rows:
        paths[int(robot)].append((float(x), float(y)))
    return paths


def team_paths_figure(
    ground_truth: GroundTruthMap,
    rows: Sequence[tuple[float, int, float, float]],
    protocol: Protocol,
    path: str | Path | None = None,
    title: str = "",
    scale: int | None = None,
    belief: np.ndarray | None = None,
) -> np.ndarray:
    """One team episode on its map: the belief its rows build, each robot's path in its colour,
    starts as squares, last positions as dots, a colour key naming each robot's distance; an RGB
    image, written as PNG to `path` when given. `rows` are a team file's (time, robot, x, y);
    `belief` is their `team_belief` when the caller has it already (the animation builds it row by row)."""
    if not rows:
        raise ValueError("a team episode has at least its start rows")
    scale = auto_scale(ground_truth.shape) if scale is None else int(scale)
    belief = team_belief(ground_truth, rows, protocol) if belief is None else belief
    image = render_frame(ground_truth, belief, [], None, scale, legend=False)
    paths = robot_paths(rows)
    thickness = max(2, int(round(scale * 0.9)))
    distances = []
    for robot, points in enumerate(paths):
        colour = ROBOT_RGB[robot % len(ROBOT_RGB)]
        pixels = ((world_to_cells(points, ground_truth) + 0.5) * scale).round().astype(np.int32)
        distances.append(float(np.hypot(*np.diff(np.asarray(points), axis=0).T).sum()) if len(points) > 1 else 0.0)
        if len(pixels) > 1:
            cv2.polylines(image, [pixels[:, None, :]], False, (255, 255, 255), thickness + 2, cv2.LINE_AA)
            cv2.polylines(image, [pixels[:, None, :]], False, colour, thickness, cv2.LINE_AA)
    for robot, points in enumerate(paths):  # markers over every path, so no path hides a start
        colour = ROBOT_RGB[robot % len(ROBOT_RGB)]
        pixels = ((world_to_cells(points, ground_truth) + 0.5) * scale).round().astype(np.int32)
        half = int(round(max(4.0, 3.0 * scale) * (1.0 - 0.6 * robot / max(1, len(paths)))))
        (sx, sy), (ex, ey) = pixels[0], pixels[-1]
        cv2.rectangle(image, (int(sx) - half, int(sy) - half), (int(sx) + half, int(sy) + half), colour, -1)
        cv2.rectangle(image, (int(sx) - half, int(sy) - half), (int(sx) + half, int(sy) + half), (255, 255, 255), 1)
        radius = max(3, int(round(1.8 * scale)))
        cv2.circle(image, (int(ex), int(ey)), radius + 1, OUTLINE_RGB, -1, cv2.LINE_AA)
        cv2.circle(image, (int(ex), int(ey)), radius, colour, -1, cv2.LINE_AA)
    header = render_header(image.shape[1], title or f"map {ground_truth.name}: {len(paths)} robots", legend=False)
    figure = np.concatenate([header, robot_key(image.shape[1], distances), image], axis=0)
    if path is not None:
        save_png(figure, path)
    return figure


def team_animation(
    ground_truth: GroundTruthMap,
    rows: Sequence[tuple[float, int, float, float]],
    protocol: Protocol,
    path: str | Path,
    frames: int = 40,
    title: str = "",
    fps: float = 8,
    hold_last_s: float = 2.0,
) -> Path:
    """An animated GIF of one team episode: `team_paths_figure` at `frames` evenly spaced team
    times from the start to the last row, each drawn from the rows up to that time (the belief
    they build, each robot's path so far in its colour). `title` heads every frame, followed by
    the frame's team time in metres of travel. The GIF's path."""
    if not rows:
        raise ValueError("a team episode has at least its start rows")
    if isinstance(frames, bool) or not isinstance(frames, int) or frames < 1:
        raise ValueError(f"frames must be a whole number >= 1, got {frames!r}")
    rows = sorted(rows, key=lambda row: row[0])  # a team file's order already; kept stable for equal times
    scale = auto_scale(ground_truth.shape)
    belief = Belief(ground_truth.shape)
    lidar = Lidar(ground_truth.free, protocol.sensor_range_cells)
    end = float(rows[-1][0])
    images, used = [], 0
    for t in np.linspace(0.0, end, frames) if frames > 1 else [end]:
        while used < len(rows) and rows[used][0] <= t + 1e-9:  # the belief grows with each row reached
            _, _, x, y = rows[used]
            belief.apply(lidar.scan(lattice_cell(ground_truth, protocol, (x, y))))
            used += 1
        text = f"{title}  |  t {t:.1f} m" if title else f"map {ground_truth.name}  |  t {t:.1f} m"
        images.append(
            team_paths_figure(ground_truth, rows[:used], protocol, None, text, scale, belief=belief.grid.copy())
        )
    return save_gif(images, path, fps=fps, hold_last_s=hold_last_s)


def robot_key(width: int, distances: Sequence[float]) -> np.ndarray:
    """A strip naming each robot's colour and distance: `robot 0: 41 m`."""
    strip = np.full((KEY_HEIGHT, width, 3), 255, dtype=np.uint8)
    x = 8
    for robot, distance in enumerate(distances):
        label = f"robot {robot}: {distance:.0f} m"
        (text_width, _), _ = cv2.getTextSize(label, FONT, 0.42, 1)
        if x + 18 + text_width > width:
            break
        cv2.rectangle(strip, (x, 7), (x + 12, 17), ROBOT_RGB[robot % len(ROBOT_RGB)], -1)
        cv2.putText(strip, label, (x + 16, 17), FONT, 0.42, (40, 40, 40), 1, cv2.LINE_AA)
        x += 16 + text_width + 14
    return strip
