"""DVC stage: draw the train and test maze sets, the office floors, and a preview figure.

Run as `python -m stages.generate_mazes` from the repository root (the package is installed).
Reads only the `mazes` section of params.yaml (plus `protocol.cell_size` when present), so
DVC reruns this stage only when those values change. Train and test mazes come from seed
sequences [seed, 0, i] and [seed, 1, i], so the two sets never share a maze. `rooms` and
`extra_loops` are per 100 m x 100 m (see `MazeConfig`), so train mazes of any side in
`side_m` have the room density of the 100 m test mazes. `mazes.offices.count` office floors
of 100 m (`pipeline.world.offices`, seed sequence [seed, 2, i]) go to data/offices/train: the sliver
gate is fitted on them beside the mazes, so that it holds on maps unlike the mazes.

A split's `kind: office` draws office floors instead of mazes (a side per floor from its
`side_m` range), and `office_scale` sets their sizes: `maze` (doors a 4 m lattice passes) or
`real_robot` (building sizes, doors from 0.8 m). `kind: building` draws floors like real plans
(`pipeline.world.buildings`: wings and courtyards, corridors with rooms on both sides, rooms of
one door, walls at any phase of the 1 m lattice, furniture) at `protocol.cell_size`:
profiles/real_robot.yaml trains on these.
A split's `plans_share` of its `count` is drawn from the real floor plans the import_plans stage
wrote to data/plans/ instead (`pipeline.world.plans.generate_plan_floors`: a plan in one of its 8
rotations and flips, cropped to a window of the split's `side_m`, a start of its own), written
beside the split's other maps as plan_NNNN.png (seed sequence [seed, split word, 1, i]); none is
drawn from the plans its `plans_exclude` names (a fold's held-out plans, so that a benchmark on
them measures plans never trained on).
The files keep the maze sets' names and folders, so every later stage reads them as it reads mazes.
"""

from __future__ import annotations

from contextlib import ExitStack
from pathlib import Path

import cv2
import numpy as np

from pipeline.common.atomic import atomic_folder
from pipeline.common.config import Section, fraction, list_of, pair, positive, text, whole
from pipeline.common.paths import DATA, REPORTS
from pipeline.stage_runner import read_protocol, read_stage, run_stage_main, stage_arguments
from pipeline.world.building_config import BuildingConfig
from pipeline.world.buildings import generate_building_set
from pipeline.world.mazes import MazeConfig, generate_maze_set, write_maze_png
from pipeline.world.offices import OFFICE_SCALES, OfficeConfig, generate_office_set
from pipeline.world.plans import generate_plan_floors, load_plan_grids

PREVIEW_PATH = REPORTS.mazes_preview
OFFICE_PREVIEW_PATH = REPORTS.offices_preview
SPLITS = {"train": 0, "test": 1}  # split name -> second word of the seed sequence
SPLIT_DIRS = {"train": DATA.mazes_train, "test": DATA.mazes_test}
OFFICE_DIR = DATA.offices_train
PLANS_DIR = DATA.plans
PLAN_SEED_WORD = 1  # a split's plan floors: seed sequence [seed, split word, PLAN_SEED_WORD, i]
OFFICE_SEED_WORD = 2
PREVIEW_COUNT = 6
PREVIEW_COLUMNS = 3
PREVIEW_TILE = 500  # pixels per preview tile side (a 100 m maze at its native size)
PREVIEW_GAP = 10
MAP_KINDS = ("maze", "office", "building")


class Split(Section):
    """One set of maps: how many, their sides, and whether mazes, office floors or building floors."""

    count: whole(0)
    side_m: pair(positive("metres"))
    kind: text(MAP_KINDS) = "maze"
    plans_share: fraction("of count drawn from data/plans") = 0.0
    plans_exclude: list_of(text(), min_length=0, description="a list of imported plans' names") = []


class Offices(Section):
    """The office floors the sliver gate is fitted on beside the mazes."""

    count: whole(0)


class Settings(Section):
    """The `mazes` section of params.yaml. block_m, rooms, room_blocks, extra_loops, offices and
    office_scale may be left out: MazeConfig's defaults, no office floors, maze-scale floors."""

    seed: whole(0)
    block_m: positive("metres") = None
    rooms: pair(whole(0, note="rooms per 100 m x 100 m")) = None
    room_blocks: pair(whole(1, note="blocks")) = None
    extra_loops: whole(0) = None
    train: Split
    test: Split
    offices: Offices = Offices(count=0)
    office_scale: text(OFFICE_SCALES) = "maze"


SplitConfig = MazeConfig | OfficeConfig | BuildingConfig


def _split_config(mazes: Settings, split: str, cell_size: float) -> tuple[SplitConfig, int]:
    """The MazeConfig (OfficeConfig for `kind: office`, BuildingConfig for `kind: building`) and
    count of one split; shared keys come from the section's top level."""
    section: Split = getattr(mazes, split)
    shared = {key: getattr(mazes, key) for key in ("block_m", "rooms", "room_blocks", "extra_loops")}
    low, high = section.side_m
    if section.kind in ("office", "building"):
        if low < 20:
            raise ValueError(
                f"params 'mazes.{split}.side_m': {section.kind} floors need sides of 20 m or more, got {low:g}"
            )
        if section.kind == "building":
            return BuildingConfig(side_m=high, cell_size=cell_size), section.count
        return OfficeConfig.for_scale(mazes.office_scale, high, cell_size), section.count
    config = MazeConfig(
        side_m=(low, high),
        cell_size=cell_size,
        **{
            key: tuple(value) if isinstance(value, list) else value
            for key, value in shared.items()
            if value is not None
        },
    )
    return config, section.count


def _draw_split(
    config: SplitConfig, count: int, folder: Path, seed: tuple[int, int], side_m: tuple[float, float]
) -> list[Path]:
    """One split's maps: mazes, or office or building floors with a side per floor from `side_m`."""
    if isinstance(config, BuildingConfig):
        return generate_building_set(config, count, folder, seed=seed, side_m=side_m)
    if isinstance(config, OfficeConfig):
        return generate_office_set(config, count, folder, seed=seed, side_m=side_m)
    return generate_maze_set(config, count, folder, seed=seed)


def _write_map_sets(
    splits: dict[str, tuple[SplitConfig, int]],
    sides: dict[str, tuple[float, float]],
    offices: int,
    office_config: OfficeConfig,
    seed: int,
    plan_floors: dict[str, int] | None = None,
    plans_exclude: dict[str, list[str]] | None = None,
    cell_size: float = 0.4,
) -> tuple[dict[str, list[Path]], list[Path]]:
    """Draw the maze splits, each split's `plan_floors` from the plans in data/plans/ but those its
    `plans_exclude` names, the office floors and both previews; (maze paths per split, office paths).

    Each set is drawn into a temporary folder, and the three replace data/mazes/{train,test} and
    data/offices/train (and whatever they held, so a smaller count leaves no stale map) only once
    every map and both previews are written: a stage killed halfway leaves the previous sets.
    The paths returned are the final ones.
    """
    with ExitStack() as stack:
        folders = {split: stack.enter_context(atomic_folder(SPLIT_DIRS[split])) for split in splits}
        office_folder = stack.enter_context(atomic_folder(OFFICE_DIR))
        drawn = {
            split: _draw_split(config, count, folders[split], (seed, SPLITS[split]), sides[split])
            for split, (config, count) in splits.items()
        }
        for split, count in (plan_floors or {}).items():
            if count:
                plans = load_plan_grids(PLANS_DIR, cell_size, exclude=(plans_exclude or {}).get(split, ()))
                seed_words = (seed, SPLITS[split], PLAN_SEED_WORD)
                drawn[split] += generate_plan_floors(plans, count, folders[split], seed_words, sides[split], cell_size)
        office_drawn = generate_office_set(office_config, offices, office_folder, seed=(seed, OFFICE_SEED_WORD))
        write_maze_png(preview_image(drawn["test"]), PREVIEW_PATH)
        write_maze_png(
            preview_image(office_drawn), OFFICE_PREVIEW_PATH
        )  # blank without floors, so the output always exists
    written = {split: [SPLIT_DIRS[split] / path.name for path in paths] for split, paths in drawn.items()}
    return written, [OFFICE_DIR / path.name for path in office_drawn]


def preview_image(paths: list[Path]) -> np.ndarray:
    """Tile up to PREVIEW_COUNT mazes in a grid, each scaled (nearest) to one tile size."""
    chosen = paths[:PREVIEW_COUNT]
    if not chosen:
        return np.full((PREVIEW_TILE, PREVIEW_TILE), 255, dtype=np.uint8)
    columns = min(PREVIEW_COLUMNS, len(chosen))
    rows = -(-len(chosen) // columns)
    step = PREVIEW_TILE + PREVIEW_GAP
    canvas = np.full((rows * step + PREVIEW_GAP, columns * step + PREVIEW_GAP), 255, dtype=np.uint8)
    for index, path in enumerate(chosen):
        maze = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        if maze is None:
            raise OSError(f"{path}: cannot read the maze just written")
        tile = cv2.resize(maze, (PREVIEW_TILE, PREVIEW_TILE), interpolation=cv2.INTER_NEAREST)
        top = PREVIEW_GAP + (index // columns) * step
        left = PREVIEW_GAP + (index % columns) * step
        canvas[top : top + PREVIEW_TILE, left : left + PREVIEW_TILE] = tile
    return canvas


def main(params_path: str = "params.yaml") -> None:
    """Write data/mazes/{train,test}/maze_NNNN.png, data/offices/train/office_NNNN.png and the previews in reports/."""
    mazes = read_stage(params_path, "mazes", Settings)
    cell_size = read_protocol(params_path).cell_size
    # Build every config first so a bad parameter fails before any file is touched.
    splits = {split: _split_config(mazes, split, cell_size) for split in SPLITS}
    plan_floors = {split: int(round(getattr(mazes, split).plans_share * count)) for split, (_, count) in splits.items()}
    splits = {split: (config, count - plan_floors[split]) for split, (config, count) in splits.items()}
    office_config = OfficeConfig.for_scale(mazes.office_scale, cell_size=cell_size)
    sides = {split: tuple(getattr(mazes, split).side_m) for split in SPLITS}
    written, office_paths = _write_map_sets(
        splits,
        sides,
        mazes.offices.count,
        office_config,
        mazes.seed,
        plan_floors,
        {split: list(getattr(mazes, split).plans_exclude) for split in SPLITS},
        cell_size,
    )
    for split, paths in written.items():
        what = {OfficeConfig: "office floors", BuildingConfig: "building floors"}.get(type(splits[split][0]), "mazes")
        from_plans = f" ({plan_floors[split]} of them from the plans in {PLANS_DIR})" if plan_floors[split] else ""
        print(f"{split}: {len(paths)} {what}{from_plans} in {SPLIT_DIRS[split]}")
    print(f"offices: {len(office_paths)} office floors in {OFFICE_DIR}")
    print(f"previews: {PREVIEW_PATH}, {OFFICE_PREVIEW_PATH}")


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
