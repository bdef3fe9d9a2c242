"""Real floor plans and saved SLAM maps as a map family: read, brought to the protocol's cells, deduplicated.

`guide plans import SRC --out DIR` (pipeline/cli/plans.py) runs `import_plans`. A source is one
file or a folder of them:

- a ROS map_server YAML with its PGM/PNG (a robot's saved SLAM map: `map_saver`, or
  `ExplorationSession.save_map`), read as map_server's trinary mode reads it;
- a PNG/PGM floor plan, whose metres per pixel the caller gives (`resolution`): free where a pixel
  is at least IMAGE_FREE_MIN (map_server's free threshold, so that a saved map's unknown grey, 205,
  is not free); a `<name>_rooms.png` beside it labels its rooms (0: none, 1..N: a room), as
  data/real_plans/kth/ ships them;
- a `.npy` grid (1 or True free; or 0-255 values read as an image's);
- a MapEx-style folder: `occ_map.npy` (0-255, free from IMAGE_FREE_MIN) with an optional
  `valid_space.npy` of room labels.

Each plan is brought to `cell_size` conservatively (a cell is free only where all its finer
cells are, `resample_map`), except where a robot of `robot_radius_m` may stand (no door it fits
through is closed); its largest free component is kept (4-connected); `starts` start cells are
drawn apart from each other where the clearance is at least START_CLEARANCE_M; and a plan equal
to one already kept, up to the 8 rotations and flips of its cropped grid at its own resolution,
is dropped.
The plans are written as ROS maps (YAML with its `start` + PGM) that `guide benchmark --maps DIR`
reads, with `manifest.json` (source, resolution, licence line, free area, rooms, starts) and the
sources' licence files beside them. Rows grow with y throughout (row 0 at the bottom), as ROS's.

For training (`mazes.train.plans_share`, stages/generate_mazes.py) `generate_plan_floors` draws
floors from imported plans as the generated families are drawn: each a plan in one of its 8
rotations and flips, cropped to a window of the split's sides, with a start of its own, so that
a few plans make many floors.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import cast

import cv2
import numpy as np

from pipeline.common.atomic import atomic_folder, atomic_write_text
from pipeline.world.map_files import MAX_GRID_CELLS, MapError, read_gray_image, read_npy_array
from pipeline.world.maps import (
    NPY_SUFFIXES,
    ROS_YAML_SUFFIXES,
    GroundTruthMap,
    list_maps,
    load_map,
    read_ros_grid,
    ros_map_origin_and_image,
)
from pipeline.world.mazes import generate_map_set
from pipeline.world.offices import render_free_map
from pipeline.world.resample import resample_map, write_ros_map

IMAGE_FREE_MIN = 206  # a pixel at least this is free: map_server's free_thresh 0.196 on (255 - p) / 255
IMAGE_SUFFIXES = (".png", ".pgm")
ROOMS_SUFFIX = "_rooms"  # <name>_rooms.png beside <name>.png: its room labels
MAPEX_GRID, MAPEX_ROOMS = "occ_map.npy", "valid_space.npy"
START_CLEARANCE_M = 0.5  # a start stands at least this far from every wall (less where no cell is this clear)
MANIFEST = "manifest.json"
LICENCE_GLOBS = ("LICENSE*", "LICENCE*", "COPYING*")
UNKNOWN_LICENCE = "unknown: say it with --licence"


@dataclass
class PlanSource:
    """One plan as read: its fine free cells (rows grow with y), metres per cell, room labels (same
    shape, 0 = none) when it has them, and where it came from."""

    name: str
    path: Path
    free: np.ndarray
    resolution: float
    rooms: np.ndarray | None = None
    licence: str = UNKNOWN_LICENCE


@dataclass
class ImportedPlan:
    """A plan at the protocol's cells, as the manifest lists it (`record`) and with its grid."""

    name: str
    source: str
    source_resolution_m: float
    cell_size_m: float
    licence: str
    free_m2: float
    shape: tuple[int, int]  # (rows, cols)
    starts: list[tuple[int, int]]  # (col, row) cells
    rooms: int | None = None
    room_area_m2: float | None = None  # mean over the labelled rooms
    key: str = ""  # equal for plans equal up to the 8 rotations and flips
    free: np.ndarray = field(default=cast(np.ndarray, None), repr=False)  # always given: a default to follow the others

    def record(self) -> dict:
        out = {k: v for k, v in asdict(self).items() if k not in ("free", "key")}
        out["starts_m"] = [
            [round((c + 0.5) * self.cell_size_m, 3), round((r + 0.5) * self.cell_size_m, 3)] for c, r in self.starts
        ]
        out["shape"] = list(self.shape)
        out["starts"] = [list(s) for s in self.starts]
        return out


# ---------------------------------------------------------------------------- reading
def find_plan_sources(src: str | Path, resolution: float | None = None, licence: str | None = None) -> list[PlanSource]:
    """Every plan in `src` (a file or a folder, see the module doc), read; MapError naming the file
    for one that cannot be (unreadable, empty, no free cell, no resolution, too large)."""
    src = Path(src)
    if not src.exists():
        raise MapError(src, "file not found")
    if resolution is not None and not (math.isfinite(resolution) and resolution > 0):
        raise MapError(src, f"resolution must be a positive number of metres per pixel, got {resolution:g}")
    if src.is_dir():
        if (src / MAPEX_GRID).is_file():
            paths = [src]
        else:
            named = {_image_of(p) for p in src.iterdir() if p.suffix.lower() in ROS_YAML_SUFFIXES}
            paths = sorted(
                p
                for p in src.iterdir()
                if (p.is_dir() and (p / MAPEX_GRID).is_file())
                or (
                    p.is_file()
                    and p.suffix.lower() in ROS_YAML_SUFFIXES + NPY_SUFFIXES + IMAGE_SUFFIXES
                    and p.resolve() not in named
                    and not p.stem.endswith(ROOMS_SUFFIX)
                )
            )
        if not paths:
            raise MapError(src, "holds no floor plan (ROS map .yaml, .png/.pgm, .npy, or a folder with occ_map.npy)")
    else:
        paths = [src]
    sources = [read_plan(path, resolution) for path in paths]
    for source in sources:
        source.licence = licence or licence_line(source.path) or UNKNOWN_LICENCE
    return sources


def _image_of(yaml_path: Path) -> Path | None:
    try:
        return ros_map_origin_and_image(yaml_path)[1].resolve()
    except MapError:
        return None


def read_plan(path: Path, resolution: float | None) -> PlanSource:
    """One plan file or MapEx folder (the module doc says how each is read)."""
    suffix = path.suffix.lower()
    if path.is_dir():
        grid = read_npy_array(path / MAPEX_GRID)
        free = _free_from_values(grid, path / MAPEX_GRID)[::-1]
        rooms_path = path / MAPEX_ROOMS
        rooms = read_npy_array(rooms_path)[::-1] if rooms_path.is_file() else None
        name = path.name
    elif suffix in ROS_YAML_SUFFIXES:
        ros = read_ros_grid(path)
        return PlanSource(path.stem, path, ros.free, ros.resolution)
    elif suffix in NPY_SUFFIXES:
        free = _free_from_values(read_npy_array(path), path)
        rooms, name = None, path.stem
    elif suffix in IMAGE_SUFFIXES:
        image = read_gray_image(path)
        free = (image >= IMAGE_FREE_MIN)[::-1]
        rooms_path = path.with_name(path.stem + ROOMS_SUFFIX + ".png")
        rooms = _read_labels(rooms_path)[::-1] if rooms_path.is_file() else None
        name = path.stem
    else:
        raise MapError(
            path, f"unknown floor plan format '{suffix}' (a ROS map .yaml, .png/.pgm, .npy or a MapEx folder)"
        )
    if resolution is None:
        raise MapError(path, "no resolution: give its metres per pixel with --resolution (a ROS map YAML says its own)")
    if rooms is not None and rooms.shape != free.shape:
        raise MapError(
            path, f"its room labels are {rooms.shape[1]}x{rooms.shape[0]}, the plan {free.shape[1]}x{free.shape[0]}"
        )
    if not free.any():
        raise MapError(path, f"no free cell (free: values of at least {IMAGE_FREE_MIN}, or 1 in a 0/1 grid)")
    return PlanSource(name, path, np.ascontiguousarray(free), float(resolution), rooms)


def _free_from_values(array: np.ndarray, path: Path) -> np.ndarray:
    if array.size == 0:
        raise MapError(path, "the grid is empty")
    if array.size > MAX_GRID_CELLS:
        raise MapError(path, f"grid of {array.size} cells exceeds the limit of {MAX_GRID_CELLS}")
    if array.dtype == bool or array.max() <= 1:
        return array.astype(bool)
    return array >= IMAGE_FREE_MIN


def _read_labels(path: Path) -> np.ndarray:
    """A room-label image at its full depth (read_gray_image would keep 8 of 16 bits)."""
    with open(path, "rb") as stream:
        data = np.frombuffer(stream.read(), dtype=np.uint8)
    labels = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if labels is None or labels.ndim != 2:
        raise MapError(path, "not a readable room-label image (one channel, 0 = no room, 1..N = a room)")
    return labels


def licence_line(path: Path) -> str | None:
    """The first line of a licence file beside `path` (in its folder, or in it for a MapEx folder)."""
    for folder in (path, path.parent) if path.is_dir() else (path.parent,):
        for pattern in LICENCE_GLOBS:
            for licence in sorted(folder.glob(pattern)):
                lines = [line.strip() for line in licence.read_text(errors="replace").splitlines() if line.strip()]
                if lines:
                    return f"{lines[0]} ({licence.name})"
    return None


# ---------------------------------------------------------------------------- converting
def convert_plan(
    source: PlanSource, cell_size: float, robot_radius_m: float, starts: int, rng: np.random.Generator
) -> ImportedPlan:
    """`source` at `cell_size`: conservative but door-keeping, its largest free component, its starts."""
    if source.resolution > cell_size * (1 + 1e-6):
        raise MapError(source.path, f"its {source.resolution:g} m cells are coarser than the {cell_size:g} m asked for")
    first = np.argwhere(source.free)[0]
    fine = GroundTruthMap(
        free=source.free, start_cell=(int(first[1]), int(first[0])), cell_size=source.resolution, name=source.name
    )
    try:
        coarse, _ = resample_map(fine, cell_size, robot_radius_m=robot_radius_m)
    except ValueError as error:
        raise MapError(source.path, str(error)) from None
    free = largest_component(coarse.free)
    rooms, room_area = count_rooms(source, free, round(cell_size / source.resolution))
    return ImportedPlan(
        name=source.name,
        source=str(source.path),
        source_resolution_m=source.resolution,
        cell_size_m=cell_size,
        licence=source.licence,
        free_m2=round(float(free.sum()) * cell_size**2, 2),
        shape=free.shape,
        starts=draw_starts(free, cell_size, starts, rng),
        rooms=rooms,
        room_area_m2=room_area,
        key=symmetry_key(source.free, source.resolution),
        free=free,
    )


def largest_component(free: np.ndarray) -> np.ndarray:
    """The largest 4-connected component of `free`."""
    count, labels, stats, _ = cv2.connectedComponentsWithStats(free.astype(np.uint8), connectivity=4)
    if count <= 1:
        return free.copy()
    return labels == 1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))


def draw_starts(free: np.ndarray, cell_size: float, count: int, rng: np.random.Generator) -> list[tuple[int, int]]:
    """`count` (col, row) cells of `free`, at least START_CLEARANCE_M from any wall where the plan
    has such cells (else its clearest), each as far from the ones before it as can be: the first
    drawn at random, the rest farthest first."""
    clearance = cv2.distanceTransform(np.pad(free, 1).astype(np.uint8), cv2.DIST_L2, 5)[1:-1, 1:-1] * cell_size
    clear = clearance >= min(START_CLEARANCE_M, float(clearance.max()))
    cells = np.argwhere(clear)
    chosen = [cells[int(rng.integers(len(cells)))]]
    nearest = np.hypot(*(cells - chosen[0]).T)
    while len(chosen) < min(count, len(cells)):
        pick = int(np.argmax(nearest))
        chosen.append(cells[pick])
        nearest = np.minimum(nearest, np.hypot(*(cells - cells[pick]).T))
    return [(int(c), int(r)) for r, c in chosen]


def count_rooms(source: PlanSource, free: np.ndarray, factor: int) -> tuple[int | None, float | None]:
    """(rooms, mean room area in m^2) of the labelled rooms with a fine free pixel in the kept cells;
    (None, None) for a plan without labels."""
    if source.rooms is None:
        return None, None
    kept = np.repeat(np.repeat(free, factor, axis=0), factor, axis=1)
    rows, cols = min(kept.shape[0], source.free.shape[0]), min(kept.shape[1], source.free.shape[1])
    labels = source.rooms[:rows, :cols]
    inside = kept[:rows, :cols] & source.free[:rows, :cols] & (labels > 0)
    ids, pixels = np.unique(labels[inside], return_counts=True)
    if not len(ids):
        return 0, None
    return int(len(ids)), round(float(pixels.mean()) * source.resolution**2, 2)


def symmetry_key(free: np.ndarray, resolution: float) -> str:
    """A digest equal for plans of one resolution whose free cells are equal after cropping to them,
    up to the 8 rotations and flips (asked of the source's own cells: at coarser cells a turned copy
    falls on other block boundaries)."""
    rows, cols = np.nonzero(free)
    crop = free[rows.min() : rows.max() + 1, cols.min() : cols.max() + 1]
    return min(
        hashlib.sha256(f"{resolution:.9g} {v.shape}".encode() + np.packbits(v).tobytes()).hexdigest()
        for v in (symmetric(crop, k) for k in range(8))
    )


# ---------------------------------------------------------------------------- writing
@dataclass
class ImportReport:
    plans: list[ImportedPlan]
    duplicates: list[tuple[str, str]]  # (dropped, the plan it equals)
    licences: list[str]  # licence files copied beside the plans


def import_plans(
    sources: list[PlanSource],
    out: str | Path,
    cell_size: float = 0.2,
    robot_radius_m: float = 0.2,
    starts: int = 3,
    seed: int = 0,
    progress=None,
) -> ImportReport:
    """Convert `sources` (`convert_plan`), drop duplicates and write them to `out` as a whole:
    `out` is replaced only once every file is written (a failure leaves it as it was)."""
    if not (math.isfinite(cell_size) and cell_size > 0):
        raise ValueError(f"cell size must be a positive number of metres, got {cell_size:g}")
    if starts < 1:
        raise ValueError(f"starts must be at least 1, got {starts}")
    rng = np.random.default_rng(seed)
    kept: dict[str, ImportedPlan] = {}
    plans, duplicates = [], []
    names: set[str] = set()
    for source in progress(sources) if progress is not None else sources:
        plan = convert_plan(source, cell_size, robot_radius_m, starts, rng)
        if plan.key in kept:
            duplicates.append((plan.name, kept[plan.key].name))
            continue
        if plan.name in names:
            raise MapError(source.path, f"a second plan named {plan.name!r}: rename one of them")
        names.add(plan.name)
        kept[plan.key] = plan
        plans.append(plan)
    licences: list[str] = []
    with atomic_folder(Path(out)) as folder:
        for plan in plans:
            col, row = plan.starts[0]
            world = GroundTruthMap(free=plan.free, start_cell=(col, row), cell_size=cell_size, name=plan.name)
            write_ros_map(world, folder / f"{plan.name}.yaml")
        for source in sources:
            for pattern in LICENCE_GLOBS:
                base = source.path if source.path.is_dir() else source.path.parent
                for licence in sorted(base.glob(pattern)):
                    if licence.name not in licences:
                        shutil.copyfile(licence, folder / licence.name)
                        licences.append(licence.name)
        manifest = {
            "cell_size_m": cell_size,
            "robot_radius_m": robot_radius_m,
            "seed": seed,
            "plans": [plan.record() for plan in plans],
            "duplicates": [{"dropped": a, "equals": b} for a, b in duplicates],
            "licence_files": licences,
        }
        atomic_write_text(folder / MANIFEST, json.dumps(manifest, indent=2) + "\n")
    return ImportReport(plans, duplicates, licences)


# ---------------------------------------------------------------------------- training floors
MIN_FLOOR_SHARE = 0.15  # a crop keeps at least this share of its window free (else another is drawn)
CROP_TRIES = 20


def symmetric(grid: np.ndarray, k: int) -> np.ndarray:
    """The `k`-th (0-7) of a grid's 8 rotations and flips."""
    return np.ascontiguousarray(np.rot90(grid[:, ::-1] if k >= 4 else grid, k % 4))


def plan_floor_image(
    plans: Sequence[np.ndarray], side_m: tuple[float, float], cell_size: float, rng: np.random.Generator
) -> np.ndarray:
    """A training floor drawn from real plans, as a map PNG image (`render_free_map`, start marked):
    a plan at random, one of its 8 rotations and flips, a window of a side drawn from `side_m`
    (the whole plan along a shorter side), its largest free component walled round, and a start
    clear of walls. Windows keep at least MIN_FLOOR_SHARE of their cells free."""
    for _ in range(CROP_TRIES):
        free = symmetric(plans[int(rng.integers(len(plans)))], int(rng.integers(8)))
        side = max(8, int(round(rng.uniform(*side_m) / cell_size)))
        rows, cols = free.shape
        height, width = min(side, rows), min(side, cols)
        top, left = int(rng.integers(rows - height + 1)), int(rng.integers(cols - width + 1))
        crop = largest_component(free[top : top + height, left : left + width])
        if crop.sum() >= MIN_FLOOR_SHARE * height * width:
            break
    crop = np.pad(crop, 1)  # walls round the window: nothing leads off the floor
    col, row = draw_starts(crop, cell_size, 1, rng)[0]
    return render_free_map(crop, (row, col))


def load_plan_grids(folder: str | Path, cell_size: float, exclude: Sequence[str] = ()) -> list[np.ndarray]:
    """The free grids of the plans `import_plans` wrote to `folder`, but those `exclude` names (by
    file stem, as the manifest names them); MapError when none is left, when a name in `exclude` is
    not there (a misspelt held-out plan would silently be trained on) or when they are not at
    `cell_size`."""
    folder = Path(folder)
    paths = list_maps(folder) if folder.is_dir() else []
    if not paths:
        raise MapError(folder, "holds no imported plans (run the import_plans stage or `guide plans import` first)")
    left_out = set(exclude)
    unknown = sorted(left_out - {path.stem for path in paths})
    if unknown:
        raise MapError(folder, f"holds no plan named {', '.join(unknown)} to leave out")
    paths = [path for path in paths if path.stem not in left_out]
    if not paths:
        raise MapError(folder, "holds no plan that is not left out (every imported plan is excluded)")
    grids = []
    for path in paths:
        plan = load_map(path)
        if abs(plan.cell_size - cell_size) > 1e-9:
            raise MapError(
                path,
                f"its cells are {plan.cell_size:g} m, the protocol's {cell_size:g} m: import the plans "
                f"at the protocol's cell size",
            )
        grids.append(plan.free)
    return grids


def generate_plan_floors(
    plans: Sequence[np.ndarray],
    count: int,
    out_dir: str | Path,
    seed: int | Sequence[int],
    side_m: tuple[float, float],
    cell_size: float,
    prefix: str = "plan",
    progress: bool = True,
) -> list[Path]:
    """Write `count` training floors drawn from `plans` (`plan_floor_image`) as `{prefix}_{i:04d}.png`,
    floor i from default_rng([*seed, i])."""
    return generate_map_set(
        lambda rng: plan_floor_image(plans, side_m, cell_size, rng), count, out_dir, seed, prefix, progress
    )
