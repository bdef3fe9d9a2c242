"""Ground-truth maps: loading the three formats of docs/protocol.md into one `GroundTruthMap`.

Every loader fails with `MapError` (file + reason) rather than a traceback, so the CLI
can print one line and exit 2 on any malformed input.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import cast

import numpy as np
import yaml

from pipeline.common.params import yaml_problem
from pipeline.world.map_files import MapError, is_file_named, read_gray_image, read_npy_array

MAZE_FREE_MIN = 150  # maze PNG: value > 150 is free ...
MAZE_FREE_BAND = (50, 80)  # ... and so is a value in [50, 80]
MAZE_START_VALUE = 208
MAZE_START_INDEX = 10  # the 11th start-marker cell in row-major order
MAZE_PNG_SUFFIXES = (".png",)
ROS_YAML_SUFFIXES = (".yaml", ".yml")
NPY_SUFFIXES = (".npy",)
MAX_YAML_BYTES = 1 << 20  # a map_server YAML is a few lines
MAX_ORIGIN_YAW = 1e-9  # radians: a ROS map rotated by more is refused (the grid is axis-aligned)
MAZE_FREE_RULE = (
    f"in a maze PNG, a cell (the minimum of a 2x2 pixel block) is free when its grey value is above "
    f"{MAZE_FREE_MIN} or within {MAZE_FREE_BAND[0]}-{MAZE_FREE_BAND[1]}"
)
NPY_FREE_RULE = "in a .npy grid, 1 or True means free and 0 or any other value is an obstacle"


@dataclass(frozen=True)
class MapFrame:
    """What a robot knows of a map before exploring it: the grid's extent, its cell size and where
    it starts. Every planner that does not see the ground truth is reset from this alone."""

    shape: tuple[int, int]  # (rows, cols)
    cell_size: float  # metres per cell
    start_cell: tuple[int, int]  # (col, row)
    name: str = "map"


def map_frame(world: "MapFrame | GroundTruthMap") -> MapFrame:
    """`world`'s frame: the frame itself, or the frame of a ground-truth map (none of its cells)."""
    return world if isinstance(world, MapFrame) else world.frame


@dataclass(frozen=True)
class GroundTruthMap:
    """A ground-truth occupancy grid: `free[row, col]` is True where the cell is free."""

    free: np.ndarray
    start_cell: tuple[int, int]  # (col, row)
    cell_size: float
    name: str = "map"
    # How this map's format decides free cells, for error messages ("in a .npy grid, 1 ..."); "" if unknown.
    free_rule: str = field(default="", compare=False, repr=False)

    @property
    def shape(self) -> tuple[int, int]:
        return self.free.shape  # type: ignore[return-value]

    @property
    def frame(self) -> MapFrame:
        """What a robot may know of this map (its extent, cell size and start), none of its cells."""
        start = cast(tuple[int, int], tuple(self.start_cell))  # (col, row)
        return MapFrame(tuple(self.free.shape), float(self.cell_size), start, self.name)

    @cached_property
    def free_cell_count(self) -> int:
        """Counted once: episodes ask at every step whether they are done (the map is never changed)."""
        return int(self.free.sum())


def validate_grid(free: np.ndarray, start_cell: tuple[int, int], path: str | Path, free_rule: str = "") -> None:
    """Reject grids the simulator cannot run: wrong rank, no free cell, bad start.

    `free_rule` (how the map's format marks free cells) is quoted when no cell is free.
    """
    if free.ndim != 2:
        raise MapError(path, f"grid must be 2-D, got {free.ndim}-D array of shape {free.shape}")
    if free.shape[0] < 1 or free.shape[1] < 1:
        raise MapError(path, f"grid is empty (shape {free.shape})")
    if not free.any():
        raise MapError(path, f"map has no free cell: {free_rule}" if free_rule else "map has no free cell")
    col, row = start_cell
    if not (0 <= col < free.shape[1] and 0 <= row < free.shape[0]):
        raise MapError(path, f"start cell (col {col}, row {row}) lies outside the {free.shape[1]}x{free.shape[0]} grid")
    if not free[row, col]:
        raise MapError(path, f"start cell (col {col}, row {row}) is on an occupied cell")


def _check_cell_size(cell_size: float, path: Path) -> float:
    try:
        value = float(cell_size)
    except (TypeError, ValueError, OverflowError):
        raise MapError(path, f"cell size must be a number, got {cell_size!r}") from None
    if not (math.isfinite(value) and value > 0):
        raise MapError(path, f"cell size must be a positive number, got {cell_size!r}")
    return value


def maze_cells_from_image(image: np.ndarray) -> np.ndarray:
    """Downsample a maze image by 2, taking the minimum of each 2x2 block (docs/protocol.md)."""
    rows, cols = image.shape[0] // 2, image.shape[1] // 2
    cropped = image[: rows * 2, : cols * 2]
    return cropped.reshape(rows, 2, cols, 2).min(axis=(1, 3))


def maze_free_mask(cells: np.ndarray) -> np.ndarray:
    low, high = MAZE_FREE_BAND
    return (cells > MAZE_FREE_MIN) | ((cells >= low) & (cells <= high))


def load_maze_png(
    path: str | Path, cell_size: float = 0.4, start_cell: tuple[int, int] | None = None
) -> GroundTruthMap:
    """Load a DARE/GUIDE maze PNG (twice the grid resolution, start marked by value 208).

    `start_cell` (col, row on the reduced grid) overrides the marker, e.g. to explore one maze
    from several starts, or gives the start of an image without one.
    """
    path = Path(path)
    cell_size = _check_cell_size(cell_size, path)
    image = read_gray_image(path)
    if image.shape[0] < 2 or image.shape[1] < 2:
        raise MapError(path, f"image of {image.shape[1]}x{image.shape[0]} pixels is too small for a 2x2 reduction")
    cells = maze_cells_from_image(image)
    if start_cell is not None:
        start = _start_cell(start_cell, path)
    else:
        rows, cols = np.nonzero(cells == MAZE_START_VALUE)
        if rows.size <= MAZE_START_INDEX:
            raise MapError(
                path,
                f"no start marker: need at least {MAZE_START_INDEX + 1} cells of value {MAZE_START_VALUE} "
                f"after the 2x2 reduction, found {rows.size}; or give the start cell (--start COL ROW)",
            )
        start = (int(cols[MAZE_START_INDEX]), int(rows[MAZE_START_INDEX]))
    free = maze_free_mask(cells)
    validate_grid(free, start, path, MAZE_FREE_RULE)
    return GroundTruthMap(free=free, start_cell=start, cell_size=cell_size, name=path.stem, free_rule=MAZE_FREE_RULE)


def _read_yaml(path: Path) -> object:
    """The parsed YAML document of a file, or MapError."""
    if not is_file_named(path):
        raise MapError(path, "file not found")
    try:
        size = path.stat().st_size
        if size > MAX_YAML_BYTES:
            raise MapError(path, f"YAML file of {size} bytes is too large for a map description")
        text = path.read_text(encoding="utf-8")
    except UnicodeDecodeError:
        raise MapError(path, "not valid YAML (the file is not UTF-8 text)") from None
    except OSError as error:
        raise MapError(path, f"cannot read the file ({error.strerror or type(error).__name__})") from None
    try:
        return yaml.safe_load(text)
    except yaml.YAMLError as error:
        raise MapError(path, f"not valid YAML ({yaml_problem(error)})") from None
    except RecursionError:
        raise MapError(path, "not valid YAML (nested too deeply)") from None


def _as_float(value: object, what: str, path: Path) -> float:
    """A finite float from a YAML value or argument, or MapError naming `what`."""
    if isinstance(value, bool) or not isinstance(value, (int, float, str, np.integer, np.floating)):
        raise MapError(path, f"{what} must be a number, got {value!r}")
    try:
        number = float(value)
    except (TypeError, ValueError, OverflowError):
        raise MapError(path, f"{what} must be a number, got {value!r}") from None
    if not math.isfinite(number):
        raise MapError(path, f"{what} must be a finite number, got {value!r}")
    return number


def _yaml_number(meta: dict, key: str, path: Path) -> float:
    if key not in meta:
        raise MapError(path, f"YAML is missing the key '{key}'")
    return _as_float(meta[key], f"YAML key '{key}'", path)


def _yaml_pair(value: object, what: str, path: Path) -> tuple[float, float]:
    if not (isinstance(value, (list, tuple, np.ndarray)) and len(value) >= 2):
        raise MapError(path, f"{what} must be a list [x, y, ...], got {value!r}")
    return _as_float(value[0], what, path), _as_float(value[1], what, path)


def read_ros_grid(path: str | Path) -> RosGrid:
    """A ROS map_server map's free cells, resolution and origin, read as map_server's trinary mode
    does (cells between the thresholds are not free); MapError naming the file for a bad one."""
    path = Path(path)
    meta = _read_yaml(path)
    if not isinstance(meta, dict):
        raise MapError(path, f"YAML must be a mapping with the map_server keys, got {type(meta).__name__}")
    if "image" not in meta:
        raise MapError(path, "YAML is missing the key 'image' (the map image's file name)")
    if not isinstance(meta["image"], str) or not meta["image"].strip():
        raise MapError(path, f"YAML key 'image' must be the map image's file name, got {meta['image']!r}")
    resolution = _yaml_number(meta, "resolution", path)
    if resolution <= 0:
        raise MapError(path, f"resolution must be positive, got {resolution}")
    if "origin" not in meta:
        raise MapError(path, "YAML is missing the key 'origin' as [x, y, yaw]")
    origin_x, origin_y = _yaml_pair(meta["origin"], "YAML key 'origin'", path)
    if len(meta["origin"]) >= 3:
        yaw = _as_float(meta["origin"][2], "YAML key 'origin' yaw", path)
        if abs(yaw) >= MAX_ORIGIN_YAW:
            raise MapError(
                path,
                f"origin yaw {yaw:g} rad is not supported; rotate the image to be axis-aligned and set the yaw to 0",
            )
    occupied_thresh = _yaml_number(meta, "occupied_thresh", path)
    free_thresh = _yaml_number(meta, "free_thresh", path)
    for key, value in (("occupied_thresh", occupied_thresh), ("free_thresh", free_thresh)):
        if not 0.0 <= value <= 1.0:
            raise MapError(path, f"YAML key '{key}' must lie in [0, 1], got {value}")
    negate = meta.get("negate", 0)
    if isinstance(negate, bool) or negate in (0, 1):
        negate = bool(negate)
    else:
        raise MapError(path, f"YAML key 'negate' must be 0 or 1, got {negate!r}")
    mode = meta.get("mode", "trinary")
    if mode not in ("trinary", "scale"):
        raise MapError(path, f"YAML key 'mode' {mode!r} is not supported (use trinary or scale)")

    image_path = Path(meta["image"])
    if not image_path.is_absolute():
        image_path = path.parent / image_path
    try:
        image = read_gray_image(image_path)
    except MapError as error:
        raise MapError(path, f"map image {error.path}: {error.reason}") from None
    # map_server: occupancy p = (255 - value) / 255 (or value / 255 when negated); p > occupied
    # is occupied, else p < free is free, else unknown. A lookup table keeps its double maths.
    values = np.arange(256, dtype=np.float64)
    occupancy = values / 255.0 if negate else (255.0 - values) / 255.0
    free_lut = ~(occupancy > occupied_thresh) & (occupancy < free_thresh)
    # map_server: image row 0 is the top (largest y); our rows grow with y, so flip.
    free = np.ascontiguousarray(free_lut[image][::-1, :])
    free_rule = _ros_free_rule(free_lut, free_thresh, occupied_thresh, negate)
    if not free.any():
        raise MapError(path, f"map has no free cell: {free_rule}")
    return RosGrid(free, resolution, (origin_x, origin_y), free_rule, meta)


@dataclass(frozen=True)
class RosGrid:
    """A map_server map's cells as `read_ros_grid` reads them: rows grow with y (row 0 at the bottom)."""

    free: np.ndarray
    resolution: float
    origin: tuple[float, float]
    free_rule: str
    meta: dict


def load_ros_map(path: str | Path, start_xy: tuple[float, float] | None = None) -> GroundTruthMap:
    """Load a ROS map_server map (YAML + PGM/PNG image) the way map_server's trinary mode does.

    The start comes from `start_xy` (metres, map frame) or from a `start: [x, y]` YAML key.
    Cells between the thresholds (map_server's "unknown") count as occupied: the ground
    truth must say free or not.
    """
    path = Path(path)
    grid = read_ros_grid(path)
    meta, free, resolution, free_rule = grid.meta, grid.free, grid.resolution, grid.free_rule
    origin_x, origin_y = grid.origin
    if start_xy is None:
        if "start" not in meta:
            raise MapError(path, "no start: pass --start X Y or add a 'start: [x, y]' key (metres, map frame)")
        start_x, start_y = _yaml_pair(meta["start"], "YAML key 'start'", path)
    else:
        start_x, start_y = _yaml_pair(start_xy, "start (x, y)", path)

    rows, cols = free.shape
    col_f = (start_x - origin_x) / resolution
    row_f = (start_y - origin_y) / resolution
    start_text = f"start ({_metres(start_x)}, {_metres(start_y)}) m"
    if not (math.isfinite(col_f) and math.isfinite(row_f) and 0 <= col_f < cols and 0 <= row_f < rows):
        raise MapError(
            path,
            f"{start_text} lies outside the map, which spans x {_metres(origin_x)} to "
            f"{_metres(origin_x + cols * resolution)} m and y {_metres(origin_y)} to "
            f"{_metres(origin_y + rows * resolution)} m ({cols}x{rows} cells of {_metres(resolution)} m)",
        )
    start = (math.floor(col_f), math.floor(row_f))
    if 0 <= start[0] < cols and 0 <= start[1] < rows and not free[start[1], start[0]]:
        raise MapError(path, f"{start_text}, cell (col {start[0]}, row {start[1]}), is on an occupied cell")
    validate_grid(free, start, path, free_rule)
    return GroundTruthMap(free=free, start_cell=start, cell_size=resolution, name=path.stem, free_rule=free_rule)


def ros_map_origin_and_image(path: str | Path) -> tuple[tuple[float, float], Path]:
    """A map_server YAML's (x, y) origin in metres (where its grid's first cell lies in the map
    frame) and the image file it names, for tools that write a map beside it."""
    path = Path(path)
    meta = _read_yaml(path)
    if not isinstance(meta, dict) or "origin" not in meta or not isinstance(meta.get("image"), str):
        raise MapError(path, "YAML needs the keys 'image' and 'origin' as [x, y, yaw]")
    return _yaml_pair(meta["origin"], "YAML key 'origin'", path), path.parent / meta["image"]


def _metres(value: float) -> str:
    """A length in metres for a message: up to 6 decimals, no trailing zeros; %g when huge."""
    if not math.isfinite(value) or abs(value) >= 1e9:
        return f"{value:.6g}"
    text = f"{value:.6f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def _ros_free_rule(free_lut: np.ndarray, free_thresh: float, occupied_thresh: float, negate: bool) -> str:
    """Which pixel values a ROS map's thresholds make free, for error messages."""
    values = np.flatnonzero(free_lut)
    settings = f"with free_thresh {free_thresh:g}, occupied_thresh {occupied_thresh:g} and negate {int(negate)}"
    if values.size == 0:
        return f"in this ROS map, {settings}, no pixel value is free"
    return f"in this ROS map, {settings}, a pixel is free when its value is within {values[0]}-{values[-1]}"


def _start_cell(start: object, path: Path) -> tuple[int, int]:
    """(col, row) as two integers, or MapError."""
    if not (isinstance(start, (list, tuple, np.ndarray)) and len(start) == 2):
        raise MapError(path, f"start cell must be two integers (col, row), got {start!r}")
    cell = []
    for value in start:
        number = _as_float(value, "start cell", path)
        if not number.is_integer():
            raise MapError(path, f"start cell must be two integers (col, row), got {tuple(start)!r}")
        cell.append(int(number))
    return cell[0], cell[1]


def load_npy_grid(path: str | Path, start_cell: tuple[int, int] | None, cell_size: float = 0.4) -> GroundTruthMap:
    """Load a NumPy boolean/uint8 grid (1 = free); the start cell (col, row) is required."""
    path = Path(path)
    cell_size = _check_cell_size(cell_size, path)
    array = read_npy_array(path)
    if start_cell is None:
        raise MapError(path, "a .npy grid needs its start cell: pass --start COL ROW")
    start = _start_cell(start_cell, path)
    free = np.ascontiguousarray(array == 1)
    if free.size and not free.any():
        raise MapError(path, f"map has no free cell: {NPY_FREE_RULE}; {_values_found(array)}")
    validate_grid(free, start, path, NPY_FREE_RULE)
    return GroundTruthMap(free=free, start_cell=start, cell_size=cell_size, name=path.stem, free_rule=NPY_FREE_RULE)


def _values_found(array: np.ndarray, shown: int = 5) -> str:
    """'the grid holds the values 0, 255' (at most `shown` of them) for an error message."""
    values = np.unique(array)
    listed = ", ".join(str(int(v)) for v in values[:shown])
    more = f" and {values.size - shown} more" if values.size > shown else ""
    noun = "value" if values.size == 1 else "values"
    return f"the grid holds the {noun} {listed}{more}"


def load_map(path: str | Path, start: tuple[float, float] | None = None, cell_size: float = 0.4) -> GroundTruthMap:
    """Load any supported map by its suffix.

    `start` is (col, row) for a .npy grid or a maze PNG (where it overrides the PNG's own
    marked start) and (x, y) metres for a ROS map. `cell_size` applies to maze PNGs and grids
    (a ROS map has its own).
    """
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in ROS_YAML_SUFFIXES:
        return load_ros_map(path, start_xy=start)
    if suffix in NPY_SUFFIXES:
        return load_npy_grid(path, cast(tuple[int, int] | None, start), cell_size)
    if suffix in MAZE_PNG_SUFFIXES:
        return load_maze_png(path, cell_size, cast(tuple[int, int] | None, start))
    if path.is_dir():
        raise MapError(path, "is a folder; pass one map file (`guide benchmark --maps` takes folders)")
    if not is_file_named(path):
        raise MapError(path, "file not found")
    raise MapError(path, f"unknown map format '{suffix}' (expected a maze .png, a ROS map .yaml or a .npy grid)")


def list_maps(directory: str | Path) -> list[Path]:
    """Every map in a directory: maze PNGs, .npy grids and ROS YAMLs (not the images a YAML names).

    Only lists; a listed file may still fail to load (with MapError) when it is malformed.
    """
    directory = Path(directory)
    if not directory.is_dir():
        raise MapError(directory, "not a directory")
    entries = sorted(entry for entry in directory.iterdir() if entry.is_file())
    named_images: set[Path] = set()
    for yaml_path in entries:
        if yaml_path.suffix.lower() not in ROS_YAML_SUFFIXES:
            continue
        try:
            meta = _read_yaml(yaml_path)
        except MapError:
            continue  # listed anyway: loading it reports what is wrong
        if isinstance(meta, dict) and isinstance(meta.get("image"), str):
            try:
                named_images.add((directory / meta["image"]).resolve())
            except (OSError, ValueError, RuntimeError):
                continue
    maps = []
    for entry in entries:
        suffix = entry.suffix.lower()
        if suffix in ROS_YAML_SUFFIXES or suffix in NPY_SUFFIXES:
            maps.append(entry)
        elif suffix in MAZE_PNG_SUFFIXES and entry.resolve() not in named_images:
            maps.append(entry)
    return maps
