"""Tests of the map loaders (pipeline/maps.py): maze PNG, ROS map_server YAML + image, .npy grid.

Every map is written into tmp_path by the test itself.
"""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pipeline.world.map_files import MapError
from pipeline.world.maps import GroundTruthMap, list_maps, load_map, load_maze_png, load_npy_grid, load_ros_map
from tests.conftest import write_ros_map

WALL, FREE, START = 127, 195, 208


# ----------------------------------------------------------------------------- helpers


def maze_cells(rows: int = 8, cols: int = 10) -> np.ndarray:
    """A cell-resolution maze: a wall border, free inside, a 3x4 start block (12 marker cells)."""
    cells = np.full((rows, cols), FREE, dtype=np.uint8)
    cells[0, :] = cells[-1, :] = WALL
    cells[:, 0] = cells[:, -1] = WALL
    cells[2:5, 3:7] = START  # rows 2..4, cols 3..6: row-major index 10 is (col 5, row 4)
    return cells


def upsample(cells: np.ndarray) -> np.ndarray:
    return np.repeat(np.repeat(cells, 2, axis=0), 2, axis=1)


def write_png(path: Path, image: np.ndarray) -> Path:
    assert cv2.imwrite(str(path), image)
    return path


def write_maze(path: Path, cells: np.ndarray) -> Path:
    return write_png(path, upsample(cells))


def write_ros(directory: Path, pixels: np.ndarray, name: str = "map", image_name: str = "map.pgm", **overrides) -> Path:
    """Write a map_server YAML + image; `overrides` replace keys, a value of None drops the key."""
    write_png(directory / image_name, pixels)
    meta = {
        "image": image_name,
        "resolution": 0.5,
        "origin": [-1.0, -2.0, 0.0],
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
        "negate": 0,
    }
    meta.update(overrides)
    meta = {key: value for key, value in meta.items() if value is not None}
    yaml_path = directory / f"{name}.yaml"
    yaml_path.write_text(yaml.safe_dump(meta))
    return yaml_path


def ros_image() -> np.ndarray:
    """A 4-row x 5-col map_server image: 254 free, 0 occupied, 205 unknown.

    Image row 0 is the top (largest y). The bottom image row (row 3) is all free except col 4.
    """
    image = np.full((4, 5), 0, dtype=np.uint8)
    image[3, :4] = 254  # bottom row: y in [-2, -1.5)
    image[2, 1] = 254
    image[1, 2] = 205  # unknown: occupied for us
    image[0, 3] = 254  # top row
    return image


def assert_map_error(path: Path, fragment: str, call) -> MapError:
    with pytest.raises(MapError) as info:
        call()
    error = info.value
    assert str(path) in str(error), str(error)
    assert fragment.lower() in error.reason.lower(), error.reason
    assert str(error) == f"{error.path}: {error.reason}"
    return error


# ----------------------------------------------------------------------------- maze PNG


def test_maze_start_is_eleventh_marker_cell(tmp_path):
    path = write_maze(tmp_path / "maze.png", maze_cells())
    grid = load_maze_png(path)
    assert isinstance(grid, GroundTruthMap)
    assert grid.shape == (8, 10)
    # markers at rows 2..4, cols 3..6 in row-major order: index 10 = row 4, col 5
    assert grid.start_cell == (5, 4)
    assert grid.name == "maze"
    assert grid.cell_size == 0.4
    assert grid.free.dtype == bool
    # interior free (markers are > 150, so free), border occupied
    assert grid.free_cell_count == 6 * 8
    assert not grid.free[0].any() and not grid.free[:, 0].any()


def test_maze_start_can_be_overridden_by_a_cell(tmp_path):
    path = write_maze(tmp_path / "maze.png", maze_cells())
    assert load_map(path, start=(2, 1)).start_cell == (2, 1)
    assert load_map(path).start_cell == (5, 4)  # the marker otherwise
    with pytest.raises(MapError, match="occupied"):
        load_map(path, start=(0, 0))
    with pytest.raises(MapError, match="two integers"):
        load_map(path, start=(2.5, 1))


def test_a_folder_is_not_a_map(tmp_path):
    with pytest.raises(MapError, match="is a folder; pass one map file"):
        load_map(tmp_path / ".")


def test_maze_start_uses_row_major_order_not_column_major(tmp_path):
    cells = np.full((6, 16), FREE, dtype=np.uint8)
    cells[1, 1:8] = START  # 7 markers on row 1
    cells[2, 1:6] = START  # 5 on row 2: the 11th (index 10) is row 2, col 4
    grid = load_maze_png(write_maze(tmp_path / "m.png", cells))
    assert grid.start_cell == (4, 2)


def test_maze_custom_cell_size(tmp_path):
    grid = load_map(write_maze(tmp_path / "maze.png", maze_cells()), cell_size=0.25)
    assert grid.cell_size == 0.25


@pytest.mark.parametrize(
    "value, free",
    [
        (0, False),
        (49, False),
        (50, True),
        (65, True),
        (80, True),
        (81, False),
        (127, False),
        (150, False),
        (151, True),
        (195, True),
        (255, True),
    ],
)
def test_maze_free_thresholds(tmp_path, value, free):
    cells = maze_cells()
    cells[6, 8] = value
    grid = load_maze_png(write_maze(tmp_path / "maze.png", cells))
    assert bool(grid.free[6, 8]) is free


def test_maze_two_by_two_minimum_reduction(tmp_path):
    image = upsample(maze_cells())
    # cell (row 6, col 1): one dark pixel of the 2x2 block makes the cell occupied
    image[13, 2] = 10
    # cell (row 6, col 2): a pixel in the [50, 80] band is the minimum -> free
    image[12, 5] = 60
    # cell (row 6, col 3): a 140 pixel among 255s -> minimum 140 -> occupied
    image[12:14, 6:8] = 255
    image[12, 7] = 140
    # cell (row 1, col 8): all four pixels 160 -> free
    image[2:4, 16:18] = 160
    grid = load_maze_png(write_png(tmp_path / "maze.png", image))
    assert not grid.free[6, 1]
    assert grid.free[6, 2]
    assert not grid.free[6, 3]
    assert grid.free[1, 8]


def test_maze_marker_cell_needs_all_four_pixels(tmp_path):
    image = upsample(maze_cells())
    # spoil one pixel of each of two marker cells: 12 - 2 = 10 markers, no start
    image[4, 6] = 207
    image[6, 9] = 255  # 255 is larger but the min-reduced cell is still 208
    image[8, 10] = 127
    path = write_png(tmp_path / "maze.png", image)
    assert_map_error(path, "no start marker", lambda: load_maze_png(path))


def test_maze_odd_size_image_crops_last_row_and_column(tmp_path):
    image = np.full((17, 21), WALL, dtype=np.uint8)
    image[:16, :20] = upsample(maze_cells())
    grid = load_maze_png(write_png(tmp_path / "maze.png", image))
    assert grid.shape == (8, 10)
    assert grid.start_cell == (5, 4)


def test_maze_colour_and_16_bit_images_are_read_as_gray(tmp_path):
    gray = upsample(maze_cells())
    colour = write_png(tmp_path / "colour.png", cv2.cvtColor(gray, cv2.COLOR_GRAY2BGR))
    deep = write_png(tmp_path / "deep.png", gray.astype(np.uint16) * 257)
    for path in (colour, deep):
        grid = load_maze_png(path)
        assert grid.start_cell == (5, 4)
        assert grid.free_cell_count == 48


# ----------------------------------------------------------------------------- ROS map


def test_ros_map_pgm_with_start_key(tmp_path):
    path = write_ros(tmp_path, ros_image(), start=[0.2, -1.9])
    grid = load_map(path)
    assert grid.shape == (4, 5)
    assert grid.cell_size == 0.5
    # origin (-1, -2), resolution 0.5: x 0.2 -> col 2, y -1.9 -> row 0 (the bottom image row)
    assert grid.start_cell == (2, 0)
    expected = np.array(
        [
            [1, 1, 1, 1, 0],  # image row 3 (bottom, smallest y)
            [0, 1, 0, 0, 0],  # image row 2
            [0, 0, 0, 0, 0],  # image row 1: 205 is unknown -> occupied
            [0, 0, 0, 1, 0],  # image row 0 (top, largest y)
        ],
        dtype=bool,
    )
    np.testing.assert_array_equal(grid.free, expected)
    assert grid.name == "map"


def test_ros_map_rows_grow_with_y(tmp_path):
    # y -0.4 -> row floor(1.6 / 0.5) = 3 counted from the bottom = image row 0 (the top);
    # x 0.6 -> col 3, which is free in image row 0
    path = write_ros(tmp_path, ros_image(), start=[0.6, -0.4])
    grid = load_ros_map(path)
    assert grid.start_cell == (3, 3)
    assert grid.free[3, 3]
    np.testing.assert_array_equal(grid.free, (ros_image() == 254)[::-1, :])


def test_ros_map_start_on_unknown_or_occupied_is_rejected(tmp_path):
    path = write_ros(tmp_path, ros_image(), start=[0.2, -0.9])  # col 2, row 2 = image row 1: unknown
    assert_map_error(path, "occupied", lambda: load_map(path))


def test_ros_map_png_image_and_explicit_start(tmp_path):
    path = write_ros(tmp_path, ros_image(), image_name="floor.png", start=[0.2, -1.9])
    assert load_map(path).start_cell == (2, 0)
    # the explicit argument wins over the YAML key
    grid = load_map(path, start=(-0.8, -1.8))
    assert grid.start_cell == (0, 0)
    assert load_ros_map(path, start_xy=(0.6, -0.4)).start_cell == (3, 3)


def test_ros_map_explicit_start_without_yaml_key(tmp_path):
    path = write_ros(tmp_path, ros_image(), image_name="floor.png")
    grid = load_ros_map(path, start_xy=(-0.5, -1.5))  # col 1, row 1 = image row 2, col 1: free
    assert grid.start_cell == (1, 1)


def test_ros_map_start_outside_grid(tmp_path):
    path = write_ros(tmp_path, ros_image())
    assert_map_error(path, "outside", lambda: load_ros_map(path, start_xy=(0.9, 0.1)))


def test_ros_map_negate(tmp_path):
    # negate: black pixels are free, white occupied
    path = write_ros(tmp_path, 255 - ros_image(), negate=1, start=[0.2, -1.9])
    grid = load_ros_map(path)
    expected = load_ros_map(write_ros(tmp_path, ros_image(), name="plain", image_name="plain.pgm", start=[0.2, -1.9]))
    # 205 -> 50 after inversion: occupancy 50/255 = 0.196 is still not below free_thresh
    np.testing.assert_array_equal(grid.free, expected.free)


def test_ros_map_thresholds(tmp_path):
    image = np.array([[0, 80, 160, 204, 206, 250]], dtype=np.uint8)
    # occupancy (255 - v) / 255: 1.0, 0.686, 0.373, 0.2, 0.192, 0.0196
    path = write_ros(tmp_path, image, free_thresh=0.196, occupied_thresh=0.65, start=[1.8, -1.9])
    np.testing.assert_array_equal(load_ros_map(path).free[0], [0, 0, 0, 0, 1, 1])
    path = write_ros(tmp_path, image, free_thresh=0.5, occupied_thresh=0.65, start=[1.8, -1.9])
    np.testing.assert_array_equal(load_ros_map(path).free[0], [0, 0, 1, 1, 1, 1])
    # map_server tests occupied first: with free_thresh above occupied_thresh, a cell above
    # occupied_thresh stays occupied
    path = write_ros(tmp_path, image, free_thresh=0.9, occupied_thresh=0.3, start=[1.8, -1.9])
    np.testing.assert_array_equal(load_ros_map(path).free[0], [0, 0, 0, 1, 1, 1])


def test_ros_map_image_path_relative_to_yaml(tmp_path, monkeypatch):
    sub = tmp_path / "maps"
    sub.mkdir()
    write_ros(sub, ros_image(), start=[0.2, -1.9])
    monkeypatch.chdir(tmp_path)
    assert load_map(Path("maps") / "map.yaml").start_cell == (2, 0)


# ----------------------------------------------------------------------------- .npy grid


def test_npy_bool_grid(tmp_path):
    grid_array = np.zeros((3, 4), dtype=bool)
    grid_array[1, 1:3] = True
    path = tmp_path / "grid.npy"
    np.save(path, grid_array)
    grid = load_map(path, start=(2, 1), cell_size=0.5)
    assert grid.shape == (3, 4)
    assert grid.start_cell == (2, 1)
    assert grid.cell_size == 0.5
    assert grid.free_cell_count == 2
    np.testing.assert_array_equal(grid.free, grid_array)


def test_npy_uint8_grid_one_is_free(tmp_path):
    grid_array = np.array([[0, 1, 2], [1, 1, 255]], dtype=np.uint8)
    path = tmp_path / "grid.npy"
    np.save(path, grid_array)
    grid = load_npy_grid(path, (0, 1))
    np.testing.assert_array_equal(grid.free, grid_array == 1)
    assert grid.free.dtype == bool


def test_npy_start_on_occupied_and_outside(tmp_path):
    path = tmp_path / "grid.npy"
    np.save(path, np.array([[0, 1], [1, 0]], dtype=np.uint8))
    assert_map_error(path, "occupied", lambda: load_map(path, start=(0, 0)))
    assert_map_error(path, "outside", lambda: load_map(path, start=(2, 0)))
    assert_map_error(path, "outside", lambda: load_map(path, start=(0, -1)))
    assert_map_error(path, "integer", lambda: load_map(path, start=(0.5, 1)))
    assert_map_error(path, "finite", lambda: load_map(path, start=(float("nan"), 1)))


# ----------------------------------------------------------------------------- list_maps


def test_list_maps(tmp_path):
    write_maze(tmp_path / "maze.png", maze_cells())
    write_ros(tmp_path, ros_image(), name="office", image_name="office.png")
    np.save(tmp_path / "grid.npy", np.ones((2, 2), dtype=bool))
    (tmp_path / "notes.txt").write_text("not a map")
    (tmp_path / "broken.yaml").write_text(": [\n")  # listed: loading it reports the error
    (tmp_path / "dir.npy").mkdir()  # a directory is not a map
    names = [path.name for path in list_maps(tmp_path)]
    assert names == ["broken.yaml", "grid.npy", "maze.png", "office.yaml"]


def test_list_maps_not_a_directory(tmp_path):
    assert_map_error(tmp_path / "nope", "not a directory", lambda: list_maps(tmp_path / "nope"))


# ----------------------------------------------------------------------------- malformed input


def test_missing_files(tmp_path):
    for name in ("gone.png", "gone.yaml", "gone.npy", "gone.pgm"):
        path = tmp_path / name
        assert_map_error(path, "file not found", lambda: load_map(path, start=(0, 0)))


def test_unreadable_image(tmp_path):
    path = tmp_path / "noise.png"
    path.write_bytes(np.random.default_rng(1).integers(0, 256, 300, dtype=np.uint8).tobytes())
    assert_map_error(path, "not a readable image", lambda: load_map(path))
    empty = tmp_path / "empty.png"
    empty.write_bytes(b"")
    assert_map_error(empty, "not a readable image", lambda: load_map(empty))


def test_image_declaring_huge_size_is_refused(tmp_path):
    path = tmp_path / "huge.pgm"
    path.write_bytes(b"P5\n# a comment\n100000 100000\n255\n" + b"\0" * 16)
    yaml_path = write_ros(tmp_path, ros_image(), start=[0.2, -1.9])
    meta = yaml.safe_load(yaml_path.read_text())
    meta["image"] = "huge.pgm"
    yaml_path.write_text(yaml.safe_dump(meta))
    error = assert_map_error(yaml_path, "exceeds the limit", lambda: load_map(yaml_path))
    assert "huge.pgm" in error.reason
    png = tmp_path / "huge.png"
    header = b"\x89PNG\r\n\x1a\n" + b"\0\0\0\x0dIHDR" + (60000).to_bytes(4, "big") * 2 + b"\x08\0\0\0\0"
    png.write_bytes(header)
    assert_map_error(png, "exceeds the limit", lambda: load_map(png))


def test_maze_without_start_marker(tmp_path):
    cells = maze_cells()
    cells[cells == START] = FREE
    path = write_maze(tmp_path / "maze.png", cells)
    error = assert_map_error(path, "no start marker", lambda: load_map(path))
    assert "--start COL ROW" in error.reason
    marked = load_map(write_maze(tmp_path / "marked.png", maze_cells()))
    given = load_map(path, start=marked.start_cell)  # the start given: no marker needed
    assert given.start_cell == marked.start_cell
    np.testing.assert_array_equal(given.free, marked.free)
    black = write_png(tmp_path / "black.png", np.zeros((8, 8), np.uint8))
    assert_map_error(black, "no free cell", lambda: load_map(black, start=(1, 1)))


def test_invalid_yaml_names_the_problem_and_where(tmp_path):
    path = tmp_path / "bad.yaml"
    path.write_text("image: a.pgm\nresolution: b: c\n")
    error = assert_map_error(path, "not valid YAML", lambda: load_map(path))
    assert error.reason == "not valid YAML (mapping values are not allowed here at line 2, column 14)"


def test_maze_with_too_few_markers(tmp_path):
    cells = maze_cells()
    cells[2, 3] = FREE
    cells[2, 4] = FREE  # 10 markers left
    path = write_maze(tmp_path / "maze.png", cells)
    error = assert_map_error(path, "no start marker", lambda: load_map(path))
    assert "found 10" in error.reason


def test_maze_too_small(tmp_path):
    path = write_png(tmp_path / "tiny.png", np.full((1, 5), FREE, dtype=np.uint8))
    assert_map_error(path, "too small", lambda: load_map(path))


def test_no_free_cell(tmp_path):
    path = tmp_path / "walls.npy"
    np.save(path, np.zeros((3, 3), dtype=np.uint8))
    assert_map_error(path, "no free cell", lambda: load_map(path, start=(1, 1)))
    ros = write_ros(tmp_path, np.zeros((3, 3), dtype=np.uint8), start=[0, 0])
    assert_map_error(ros, "no free cell", lambda: load_map(ros))


@pytest.mark.parametrize("key", ["image", "resolution", "origin", "occupied_thresh", "free_thresh"])
def test_yaml_missing_required_key(tmp_path, key):
    path = write_ros(tmp_path, ros_image(), start=[0.2, -1.9], **{key: None})
    error = assert_map_error(path, "missing the key", lambda: load_map(path))
    assert f"'{key}'" in error.reason


@pytest.mark.parametrize(
    "overrides, fragment",
    [
        ({"resolution": 0}, "resolution must be positive"),
        ({"resolution": -0.1}, "resolution must be positive"),
        ({"resolution": "fast"}, "must be a number"),
        ({"resolution": float("nan")}, "finite"),
        ({"resolution": [0.05]}, "must be a number"),
        ({"origin": [1.0]}, "origin"),
        ({"origin": "here"}, "origin"),
        ({"origin": [float("inf"), 0, 0]}, "finite"),
        ({"origin": [10**400, 0, 0]}, "origin"),
        ({"free_thresh": 1.5}, "[0, 1]"),
        ({"occupied_thresh": -0.2}, "[0, 1]"),
        ({"negate": "yes"}, "negate"),
        ({"negate": 2}, "negate"),
        ({"mode": "raw"}, "mode"),
        ({"image": 12}, "file name"),
        ({"image": ""}, "file name"),
        ({"image": "missing.pgm"}, "file not found"),
        ({"start": [0.2]}, "start"),
        ({"start": ["a", "b"]}, "start"),
        ({"start": [1e308, 0]}, "outside"),
        ({"start": None}, "no start"),
    ],
)
def test_yaml_bad_values(tmp_path, overrides, fragment):
    path = write_ros(tmp_path, ros_image(), **{"start": [0.2, -1.9], **overrides})
    assert_map_error(path, fragment, lambda: load_map(path))


def test_yaml_image_missing_names_both_files(tmp_path):
    path = write_ros(tmp_path, ros_image(), image="absent.pgm", start=[0.2, -1.9])
    error = assert_map_error(path, "file not found", lambda: load_map(path))
    assert "absent.pgm" in error.reason


@pytest.mark.parametrize("text", ["- a\n- b\n", "just a string\n", "42\n", "", "null\n"])
def test_yaml_not_a_mapping(tmp_path, text):
    path = tmp_path / "map.yaml"
    path.write_text(text)
    assert_map_error(path, "must be a mapping", lambda: load_map(path, start=(0, 0)))


def test_yaml_invalid(tmp_path):
    path = tmp_path / "map.yaml"
    path.write_text("image: [unclosed\n")
    assert_map_error(path, "not valid yaml", lambda: load_map(path))
    path.write_bytes(b"image: \xff\xfe\n")
    assert_map_error(path, "not valid yaml", lambda: load_map(path))
    path.write_text("[" * 1000 + "]" * 1000)  # nesting deep enough to exhaust the parser
    assert_map_error(path, "yaml", lambda: load_map(path))


def test_yaml_image_unreadable(tmp_path):
    (tmp_path / "map.pgm").write_bytes(b"not an image at all")
    meta = {
        "image": "map.pgm",
        "resolution": 0.1,
        "origin": [0, 0, 0],
        "occupied_thresh": 0.65,
        "free_thresh": 0.2,
        "start": [0, 0],
    }
    path = tmp_path / "map.yaml"
    path.write_text(yaml.safe_dump(meta))
    error = assert_map_error(path, "not a readable image", lambda: load_map(path))
    assert "map.pgm" in error.reason


@pytest.mark.parametrize("shape", [(5,), (2, 2, 2), (), (1, 1, 1, 1)])
def test_npy_not_two_d(tmp_path, shape):
    path = tmp_path / "grid.npy"
    np.save(path, np.ones(shape, dtype=np.uint8))
    assert_map_error(path, "2-D", lambda: load_map(path, start=(0, 0)))


@pytest.mark.parametrize(
    "array",
    [
        np.ones((2, 2), dtype=np.float64),
        np.ones((2, 2), dtype=np.float32),
        np.ones((2, 2), dtype=np.complex64),
        np.array([["a", "b"], ["c", "d"]]),
        np.zeros((2, 2), dtype=[("a", np.uint8)]),
    ],
)
def test_npy_wrong_dtype(tmp_path, array):
    path = tmp_path / "grid.npy"
    np.save(path, array)
    assert_map_error(path, "boolean or integer", lambda: load_map(path, start=(0, 0)))


def test_npy_object_dtype(tmp_path):
    path = tmp_path / "grid.npy"
    array = np.empty((2, 2), dtype=object)
    array[:] = 1
    np.save(path, array, allow_pickle=True)
    assert_map_error(path, "boolean or integer", lambda: load_map(path, start=(0, 0)))


def test_npy_without_start(tmp_path):
    path = tmp_path / "grid.npy"
    np.save(path, np.ones((2, 2), dtype=bool))
    assert_map_error(path, "start cell", lambda: load_map(path))


def test_npy_empty_grid(tmp_path):
    path = tmp_path / "grid.npy"
    np.save(path, np.ones((0, 3), dtype=bool))
    assert_map_error(path, "empty", lambda: load_map(path, start=(0, 0)))


def test_npy_corrupt_files(tmp_path):
    path = tmp_path / "grid.npy"
    path.write_bytes(b"\x93NUMPY garbage")
    assert_map_error(path, "not a readable .npy", lambda: load_map(path, start=(0, 0)))
    np.savez(tmp_path / "archive.npz", grid=np.ones((2, 2), dtype=bool))
    zipped = tmp_path / "zipped.npy"
    zipped.write_bytes((tmp_path / "archive.npz").read_bytes())
    assert_map_error(zipped, "not a readable .npy", lambda: load_map(zipped, start=(0, 0)))


def test_npy_truncated_and_huge_header(tmp_path):
    path = tmp_path / "grid.npy"
    np.save(path, np.ones((50, 50), dtype=np.uint8))
    path.write_bytes(path.read_bytes()[:-100])
    assert_map_error(path, "truncated", lambda: load_map(path, start=(0, 0)))
    # a header claiming a gigantic grid is refused before any allocation
    np.save(path, np.ones((2, 2), dtype=np.uint8))
    data = path.read_bytes().replace(b"(2, 2)", b"(99999999, 9)")
    path.write_bytes(data)
    assert_map_error(path, "exceeds the limit", lambda: load_map(path, start=(0, 0)))


def test_unknown_suffix(tmp_path):
    path = tmp_path / "map.bmp"
    path.write_bytes(b"BM")
    error = assert_map_error(path, "unknown map format", lambda: load_map(path))
    assert "'.bmp'" in error.reason


def test_bad_cell_size(tmp_path):
    path = write_maze(tmp_path / "maze.png", maze_cells())
    assert_map_error(path, "cell size", lambda: load_map(path, cell_size=0))
    assert_map_error(path, "cell size", lambda: load_map(path, cell_size=float("inf")))


# ----------------------------------------------------------------------------- fuzzing

FUZZ = settings(
    max_examples=80,
    deadline=None,
    derandomize=True,
    database=None,  # the same examples on every run
    suppress_health_check=[HealthCheck.function_scoped_fixture],
)


def load_or_map_error(path: Path, start=None) -> None:
    """The only acceptable outcomes: a GroundTruthMap or a MapError naming the file."""
    try:
        result = load_map(path, start=start)
    except MapError as error:
        assert error.reason
        assert str(path) in str(error)
        return
    assert isinstance(result, GroundTruthMap)
    assert result.free.ndim == 2 and result.free.dtype == bool
    col, row = result.start_cell
    assert result.free[row, col]


@FUZZ
@given(data=st.binary(max_size=600), suffix=st.sampled_from([".png", ".pgm", ".npy", ".yaml"]))
def test_fuzz_random_bytes(tmp_path, data, suffix):
    path = tmp_path / f"fuzz{suffix}"
    path.write_bytes(data)
    load_or_map_error(path)
    load_or_map_error(path, start=(0, 0))


PREFIXES = [
    b"",
    b"\x89PNG\r\n\x1a\n",
    b"P5\n",
    b"P2\n4 4\n255\n",
    b"\x93NUMPY\x01\x00",
    b"image: map.pgm\nresolution: ",
]


@FUZZ
@given(
    prefix=st.sampled_from(PREFIXES),
    data=st.binary(max_size=200),
    suffix=st.sampled_from([".png", ".pgm", ".npy", ".yaml"]),
)
def test_fuzz_plausible_headers(tmp_path, prefix, data, suffix):
    path = tmp_path / f"fuzz{suffix}"
    path.write_bytes(prefix + data)
    load_or_map_error(path, start=(1, 1))
    # the same bytes as the image a YAML names
    (tmp_path / "map.pgm").write_bytes(prefix + data)
    meta = {
        "image": "map.pgm",
        "resolution": 0.5,
        "origin": [0, 0, 0],
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
        "start": [0.1, 0.1],
    }
    (tmp_path / "map.yaml").write_text(yaml.safe_dump(meta))
    load_or_map_error(tmp_path / "map.yaml")


DTYPES = [
    np.bool_,
    np.uint8,
    np.int8,
    np.uint16,
    np.int32,
    np.int64,
    np.float32,
    np.float64,
    np.complex64,
    ">u2",
    "<i8",
    "U3",
    "S2",
]


@FUZZ
@given(
    shape=st.lists(st.integers(0, 5), min_size=0, max_size=4),
    dtype=st.sampled_from(DTYPES),
    seed=st.integers(0, 2**32 - 1),
    start=st.one_of(st.none(), st.tuples(st.integers(-2, 6), st.integers(-2, 6))),
)
def test_fuzz_random_arrays(tmp_path, shape, dtype, seed, start):
    rng = np.random.default_rng(seed)
    array = rng.integers(0, 3, size=shape).astype(dtype)
    path = tmp_path / "fuzz.npy"
    np.save(path, array)
    load_or_map_error(path, start=start)
    # a well-formed 2-D grid of an accepted dtype with a start on a free cell must load
    if (
        array.ndim == 2
        and np.dtype(dtype).kind in "biu"
        and start is not None
        and 0 <= start[0] < array.shape[1]
        and 0 <= start[1] < array.shape[0]
        and array[start[1], start[0]] == 1
    ):
        grid = load_map(path, start=start)
        np.testing.assert_array_equal(grid.free, array == 1)


@FUZZ
@given(
    rows=st.integers(1, 6),
    cols=st.integers(1, 6),
    dtype=st.sampled_from([np.bool_, np.uint8, np.int8, np.uint16, np.int32, np.int64, ">u2", "<i8"]),
    seed=st.integers(0, 2**32 - 1),
    start_index=st.integers(0, 35),
)
def test_fuzz_well_formed_grids_load(tmp_path, rows, cols, dtype, seed, start_index):
    """Any 2-D integer or boolean grid with the start on a free (1) cell loads, cell for cell."""
    rng = np.random.default_rng(seed)
    array = rng.integers(0, 2 if np.dtype(dtype).kind == "b" else 3, size=(rows, cols))
    row, col = divmod(start_index % (rows * cols), cols)
    array[row, col] = 1
    array = array.astype(dtype)
    path = tmp_path / "grid.npy"
    np.save(path, array)
    grid = load_map(path, start=(col, row))
    np.testing.assert_array_equal(grid.free, array == 1)
    assert grid.start_cell == (col, row)


YAML_VALUES = st.recursive(
    st.none() | st.booleans() | st.integers(-(10**20), 10**20) | st.floats() | st.text(max_size=8),
    lambda children: st.lists(children, max_size=3) | st.dictionaries(st.text(max_size=5), children, max_size=3),
    max_leaves=6,
)


@FUZZ
@given(
    values=st.fixed_dictionaries(
        {},
        optional={
            key: YAML_VALUES
            for key in ("image", "resolution", "origin", "occupied_thresh", "free_thresh", "negate", "start", "mode")
        },
    )
)
def test_fuzz_yaml_values(tmp_path, values):
    write_png(tmp_path / "real.pgm", ros_image())
    meta = {
        "image": "real.pgm",
        "resolution": 0.5,
        "origin": [-1, -2, 0],
        "occupied_thresh": 0.65,
        "free_thresh": 0.196,
        "start": [0.2, -1.9],
    }
    meta.update(values)
    path = tmp_path / "fuzz.yaml"
    path.write_text(yaml.safe_dump(meta, allow_unicode=True))
    load_or_map_error(path)


# ----------------------------------------------------------------------------- format-specific messages


def test_npy_image_style_grid_says_one_is_free_and_lists_values(tmp_path):
    path = tmp_path / "image_style.npy"
    np.save(path, np.where(np.eye(4, dtype=bool), 255, 0).astype(np.uint8))  # 0/255, as an image
    error = assert_map_error(path, "no free cell", lambda: load_map(path, start=(0, 0)))
    assert "in a .npy grid, 1 or True means free" in error.reason
    assert "the values 0, 255" in error.reason
    assert "grey" not in error.reason and "150" not in error.reason  # no PNG thresholds for a grid
    many = tmp_path / "many.npy"
    np.save(many, np.arange(2, 30).reshape(4, 7))
    error = assert_map_error(many, "no free cell", lambda: load_map(many, start=(0, 0)))
    assert "the values 2, 3, 4, 5, 6 and 23 more" in error.reason


def test_ros_no_free_cell_names_the_free_pixel_values(tmp_path):
    path = write_ros(tmp_path, np.zeros((3, 3), dtype=np.uint8), start=[0, 0])
    error = assert_map_error(path, "no free cell", lambda: load_map(path))
    # (255 - v) / 255 < 0.196  <=>  v >= 206
    assert "a pixel is free when its value is within 206-255" in error.reason
    assert "free_thresh 0.196" in error.reason and "grey value is above" not in error.reason
    none_free = write_ros(tmp_path, ros_image(), name="none", free_thresh=0.0, start=[0.2, -1.9])
    assert_map_error(none_free, "no pixel value is free", lambda: load_map(none_free))


def test_loaded_maps_carry_their_format_free_rule(tmp_path):
    maze = load_map(write_maze(tmp_path / "maze.png", maze_cells()))
    assert "maze PNG" in maze.free_rule and "150" in maze.free_rule
    np.save(tmp_path / "grid.npy", np.ones((3, 3), dtype=np.uint8))
    grid = load_map(tmp_path / "grid.npy", start=(1, 1))
    assert ".npy grid" in grid.free_rule and "150" not in grid.free_rule
    ros = load_map(write_ros(tmp_path, ros_image(), start=[0.2, -1.9]))
    assert "ROS map" in ros.free_rule and "206-255" in ros.free_rule


# ----------------------------------------------------------------------------- corrupt images stay quiet


@pytest.mark.parametrize("cut", [8, 40, None])
def test_corrupt_png_prints_nothing_but_the_error(tmp_path, capfd, cut):
    good = write_png(tmp_path / "good.png", upsample(maze_cells()))
    data = good.read_bytes()
    path = tmp_path / "corrupt.png"
    path.write_bytes(data[:cut] if cut is not None else data[: len(data) // 2])
    level = cv2.utils.logging.getLogLevel()
    capfd.readouterr()
    assert_map_error(path, "not a readable image", lambda: load_map(path))
    captured = capfd.readouterr()
    assert captured.err == "" and captured.out == "", captured.err  # no "[ WARN:0@...]" lines
    assert cv2.utils.logging.getLogLevel() == level  # OpenCV's level is restored
    # the image a ROS YAML names goes through the same decoder
    (tmp_path / "map.pgm").write_bytes(path.read_bytes())
    ros = tmp_path / "map.yaml"
    ros.write_text(
        yaml.safe_dump(
            {
                "image": "map.pgm",
                "resolution": 0.5,
                "origin": [0, 0, 0],
                "occupied_thresh": 0.65,
                "free_thresh": 0.196,
                "start": [0.1, 0.1],
            }
        )
    )
    assert_map_error(ros, "not a readable image", lambda: load_map(ros))
    assert capfd.readouterr().err == ""


# ----------------------------------------------------------------------------- ROS origin yaw and start


@pytest.mark.parametrize("yaw", [0.3, -1.5707963, 1e-6])
def test_ros_origin_yaw_is_refused(tmp_path, yaw):
    path = write_ros(tmp_path, ros_image(), origin=[-1.0, -2.0, yaw], start=[0.2, -1.9])
    error = assert_map_error(path, "origin yaw", lambda: load_map(path))
    assert "not supported" in error.reason and "rotate the image" in error.reason


@pytest.mark.parametrize("origin", [[-1.0, -2.0, 0.0], [-1.0, -2.0, -0.0], [-1.0, -2.0, 1e-12], [-1.0, -2.0]])
def test_ros_origin_without_yaw_still_loads(tmp_path, origin):
    path = write_ros(tmp_path, ros_image(), origin=origin, start=[0.2, -1.9])
    grid = load_map(path)
    assert grid.start_cell == (2, 0)
    np.testing.assert_array_equal(grid.free, (ros_image() == 254)[::-1, :])


@pytest.mark.parametrize("yaw", ["east", float("nan"), float("inf"), None])
def test_ros_origin_yaw_must_be_a_finite_number(tmp_path, yaw):
    path = write_ros(tmp_path, ros_image(), origin=[-1.0, -2.0, yaw], start=[0.2, -1.9])
    assert_map_error(path, "yaw", lambda: load_map(path))


def test_ros_start_outside_is_reported_in_metres_with_the_map_extent(tmp_path):
    free = np.zeros((70, 120), dtype=bool)
    free[10:60, 10:110] = True
    path = write_ros_map(tmp_path, free, 0.05, (100, 100))
    error = assert_map_error(path, "outside", lambda: load_map(path))
    assert "start (100, 100) m" in error.reason
    assert "x 0 to 6 m and y 0 to 3.5 m" in error.reason and "120x70 cells of 0.05 m" in error.reason
    assert "col" not in error.reason  # the user gave metres, not cells
    # non-zero origin; an explicit start; one that overflows the cell arithmetic
    shifted = write_ros(tmp_path, ros_image(), name="shifted", start=[0.2, -1.9])
    error = assert_map_error(shifted, "outside", lambda: load_ros_map(shifted, start_xy=(0.9, 0.1)))
    assert "start (0.9, 0.1) m" in error.reason and "x -1 to 1.5 m and y -2 to 0 m" in error.reason
    error = assert_map_error(shifted, "outside", lambda: load_ros_map(shifted, start_xy=(1e308, 0)))
    assert "start (1e+308, 0) m" in error.reason


def test_ros_start_on_occupied_cell_is_reported_in_metres(tmp_path):
    path = write_ros(tmp_path, ros_image(), start=[0.2, -0.9])
    error = assert_map_error(path, "is on an occupied cell", lambda: load_map(path))
    assert "start (0.2, -0.9) m" in error.reason and "(col 2, row 2)" in error.reason
