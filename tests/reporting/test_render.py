"""Tests of the trajectory figures (pipeline/render.py): frames, recorder, GIF, PNG, panels.

Every map is built in the test; files go to tmp_path.
"""

from __future__ import annotations

import cv2
import numpy as np
import pytest
from PIL import Image

from pipeline.planners import make_planner
from pipeline.planners.wrapper import innermost
from pipeline.reporting import panels, render
from pipeline.reporting.recorder import EpisodeRecorder
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE, OCCUPIED, UNKNOWN
from pipeline.world.simulator import run_episode

ROWS, COLS = 60, 80


def small_map() -> GroundTruthMap:
    """A walled box split by a wall with a door, a room with a door on the right, a pillar."""
    free = np.zeros((ROWS, COLS), dtype=bool)
    free[1:-1, 1:-1] = True
    free[:, 40] = False
    free[26:34, 40] = True  # door between the halves
    free[30, 41:] = False
    free[30, 60:66] = True  # door into the lower right room
    free[10:20, 15:25] = False  # pillar
    return GroundTruthMap(free=free, start_cell=(20, 40), cell_size=0.4, name="tiny")


def run_recorded(max_frames: int = 50, every: int = 1, scale: int = 3):
    ground_truth = small_map()
    planner = make_planner("nearest_frontier")
    recorder = EpisodeRecorder(
        every=every,
        max_frames=max_frames,
        graph_provider=lambda: innermost(planner).graph,
        scale=scale,
        label=planner.name,
    )
    seen = []

    def on_step(episode):
        seen.append((episode.steps, episode.cell, episode.belief.grid.copy()))
        recorder(episode)

    result = run_episode(ground_truth, planner, Protocol(max_steps=5), on_step=on_step)
    return ground_truth, planner, recorder, result, seen


@pytest.fixture(scope="module")
def recorded():
    return run_recorded()


def header_height(width: int, graph_shown: bool = True) -> int:
    header = render.render_header(width, "x", True, graph_shown=graph_shown)
    return header.shape[0]


def is_path_colour(pixel: np.ndarray, n_segments: int, tolerance: int = 2) -> bool:
    colours = render.path_colours(n_segments).astype(int)
    return bool((np.abs(colours - pixel.astype(int)).max(axis=1) <= tolerance).any())


# ----------------------------------------------------------------------------- render_frame


def test_frame_shape_dtype_and_layers():
    ground_truth = small_map()
    belief = np.full(ground_truth.shape, UNKNOWN, dtype=np.uint8)
    belief[35:45, 5:15] = FREE
    belief[34, 5:15] = OCCUPIED
    scale = 2
    image = render.render_frame(ground_truth, belief, [], None, scale=scale, title="t")
    top = header_height(COLS * scale, graph_shown=False)
    assert image.dtype == np.uint8
    assert image.shape == (top + ROWS * scale, COLS * scale, 3)

    def cell_pixel(col: int, row: int) -> tuple[int, ...]:
        return tuple(int(v) for v in image[top + row * scale, col * scale])

    assert cell_pixel(10, 40) == render.FREE_RGB
    assert cell_pixel(10, 34) == render.OCCUPIED_RGB
    assert cell_pixel(60, 45) == render.UNKNOWN_FREE_RGB  # unexplored free space
    assert cell_pixel(40, 10) == render.UNKNOWN_WALL_RGB  # unexplored wall, shown faintly


def test_y_up_draws_the_map_upside_down_under_the_same_title():
    """A ROS map's rows grow with y: drawn with y_up its image reads like the map file."""
    ground_truth = small_map()
    belief = np.full(ground_truth.shape, UNKNOWN, dtype=np.uint8)
    belief[35:45, 5:15] = FREE
    plain = render.render_frame(ground_truth, belief, [(0.0, 0.0), (4.0, 0.0)], None, scale=2, title="t")
    flipped = render.render_frame(ground_truth, belief, [(0.0, 0.0), (4.0, 0.0)], None, scale=2, title="t", y_up=True)
    top = header_height(COLS * 2, graph_shown=False)
    assert np.array_equal(flipped[:top], plain[:top])
    assert np.array_equal(flipped[top:], plain[top:][::-1])
    assert not np.array_equal(flipped[top:], plain[top:])


def test_frame_marks_frontier_cells():
    ground_truth = small_map()
    belief = np.full(ground_truth.shape, UNKNOWN, dtype=np.uint8)
    belief[35:45, 5:15] = FREE
    scale = 2
    image = render.render_frame(ground_truth, belief, [], None, scale=scale, legend=False)
    assert image.shape == (ROWS * scale, COLS * scale, 3)  # no title, no legend: no header
    # The block's right edge borders unknown space: frontier; its inside does not.
    assert tuple(image[40 * scale, 14 * scale]) == render.FRONTIER_RGB
    assert tuple(image[40 * scale, 10 * scale]) == render.FREE_RGB


def test_path_pixels_are_coloured_along_the_path():
    ground_truth = small_map()
    belief = np.where(ground_truth.free, FREE, OCCUPIED).astype(np.uint8)
    scale = 3
    # Start (20, 40); 4 m = 10 cells per step: right, right, up, up.
    trajectory = [(0.0, 0.0), (4.0, 0.0), (8.0, 0.0), (8.0, -4.0), (8.0, -8.0)]
    image = render.render_frame(ground_truth, belief, trajectory, None, scale=scale, legend=False)
    cells = render.world_to_cells(trajectory, ground_truth)
    assert cells.tolist() == [[20, 40], [30, 40], [40, 40], [40, 30], [40, 20]]
    colours = render.path_colours(len(trajectory) - 1)
    for i in range(len(cells) - 1):
        mid = (cells[i] + cells[i + 1]) / 2.0
        px, py = ((mid + 0.5) * scale).astype(int)
        pixel = image[py, px].astype(int)
        assert np.abs(pixel - colours[i].astype(int)).max() <= 2, (i, pixel, colours[i])
    # Graded: the first segment is the start colour, the last the end colour.
    assert tuple(colours[0]) == render.PATH_STOPS[0]
    assert tuple(colours[-1]) == render.PATH_STOPS[-1]
    # Off the path (a free cell far away) keeps the map colour.
    assert tuple(image[int(50.5 * scale), int(70.5 * scale)]) == render.FREE_RGB
    # Markers: the start square and the robot disc.
    sx, sy = ((np.array([20, 40]) + 0.5) * scale).astype(int)
    assert tuple(image[sy, sx]) == render.START_RGB
    rx, ry = ((np.array([40, 20]) + 0.5) * scale).astype(int)
    assert tuple(image[ry, rx]) == render.ROBOT_RGB


def test_frame_rejects_a_belief_of_another_shape():
    with pytest.raises(ValueError):
        render.render_frame(small_map(), np.zeros((3, 3), np.uint8), [(0.0, 0.0)])


# ----------------------------------------------------------------------------- recorder


def test_recorder_frames_match_the_episode(recorded):
    ground_truth, planner, recorder, result, seen = recorded
    frames = recorder.frames
    assert result.steps >= 2
    assert len(frames) == len(seen) == result.steps + 1
    scale = recorder.scale
    top = header_height(COLS * scale)
    for frame in frames:
        assert frame.dtype == np.uint8
        assert frame.shape == (top + ROWS * scale, COLS * scale, 3)
    assert recorder.steps == [s for s, _, _ in seen]
    # World -> cell as the simulator does it.
    assert render.world_to_cells(result.trajectory, ground_truth).tolist() == [list(c) for _, c, _ in seen]
    # The last frame shows the path: each segment's midpoint wears a path colour.
    final = frames[-1][top:]
    cells = render.world_to_cells(result.trajectory, ground_truth)
    n = len(cells) - 1
    for i in range(n):
        px, py = (((cells[i] + cells[i + 1]) / 2.0 + 0.5) * scale).astype(int)
        assert is_path_colour(final[py, px], n), (i, final[py, px])
    # Frames change as the robot explores.
    assert not np.array_equal(frames[0], frames[-1])


def test_recorder_keeps_at_most_max_frames_evenly_spaced():
    _, _, recorder, result, seen = run_recorded(max_frames=3, scale=1)
    steps = recorder.steps
    assert len(recorder.frames) == len(steps) <= 3
    assert steps[0] == 0
    assert steps[-1] == seen[-1][0]  # the final state is always the last frame
    gaps = np.diff(steps[:-1])
    assert len(set(gaps.tolist())) <= 1


def test_recorder_every_n_steps():
    _, _, recorder, _, seen = run_recorded(every=2, scale=1)
    last = seen[-1][0]
    expected = list(range(0, last + 1, 2))
    if expected[-1] != last:
        expected.append(last)
    assert recorder.steps == expected


def test_gif_is_animated_and_holds_the_last_frame(recorded, tmp_path):
    _, _, recorder, _, _ = recorded
    path = recorder.save_gif(tmp_path / "episode.gif", fps=10)
    with Image.open(path) as gif:
        assert gif.format == "GIF"
        assert gif.n_frames > 1
        assert gif.info.get("loop") == 0
        assert gif.size == (recorder.frames[0].shape[1], recorder.frames[0].shape[0])
        gif.seek(0)
        first_ms = gif.info["duration"]
        gif.seek(gif.n_frames - 1)
        assert gif.info["duration"] > first_ms
        last = np.asarray(gif.convert("RGB")).astype(int)
    # Palette quantisation keeps the picture close to the rendered frame.
    assert np.abs(last - recorder.frames[-1].astype(int)).mean() < 3.0


def test_save_gif_needs_frames(tmp_path):
    with pytest.raises(ValueError):
        render.save_gif([], tmp_path / "empty.gif")


# ----------------------------------------------------------------------------- files and reports


def test_save_png_round_trips_through_cv2(recorded, tmp_path):
    _, _, recorder, _, _ = recorded
    image = recorder.frames[-1]
    path = render.save_png(image, tmp_path / "sub" / "frame.png")
    loaded = cv2.imread(str(path), cv2.IMREAD_COLOR)
    assert loaded is not None
    assert np.array_equal(cv2.cvtColor(loaded, cv2.COLOR_BGR2RGB), image)


def test_render_final_writes_the_png(recorded, tmp_path):
    ground_truth, planner, _, result, seen = recorded
    belief = seen[-1][2]
    image = panels.render_final(
        result, ground_truth, belief, innermost(planner).graph, scale=2, path=tmp_path / "final.png"
    )
    assert image.shape == (header_height(COLS * 2) + ROWS * 2, COLS * 2, 3)
    loaded = cv2.imread(str(tmp_path / "final.png"))
    assert loaded is not None and loaded.shape == image.shape


def test_render_comparison_puts_panels_in_a_row(recorded):
    ground_truth, _, _, result, seen = recorded
    results = [
        ("a", result.trajectory, result.distance_m),
        ("b", result.trajectory[:3], 8.0, seen[2][2]),
        ("c", [(0.0, 0.0)], 0.0, None),
    ]
    image = panels.render_comparison(ground_truth, results, scale=2, gap=4)
    assert image.dtype == np.uint8
    assert image.shape[1] == 3 * COLS * 2 + 4 * 4
    assert image.shape[0] > ROWS * 2
    with pytest.raises(ValueError):
        panels.render_comparison(ground_truth, [])


def test_header_height_does_not_depend_on_the_title():
    short = render.render_header(500, "a")
    long = render.render_header(500, "a much longer title " * 10)
    assert short.shape == long.shape
    assert render.render_header(500, "", legend=False) is None
