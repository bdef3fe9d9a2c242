"""Real floor plans and generated building floors, measured the same way, side by side.

Usage: python benchmarks/floor_statistics.py [--plans data/real_plans/kth] [--count 30] [--seed 0]
                                             [--side 20 80] [--figure docs/buildings.png]

Reads the labelled plans in `--plans` (0.05 m per pixel, each with its `<id>_rooms.png`) and
brings them to 0.2 m cells as the plan import does (`pipeline.world.floor_shape.real_plan_grids`),
draws `--count` building floors (`pipeline.world.buildings`; floor i from default_rng([seed, i]),
its side drawn in whole metres from `--side`), and prints one markdown table: a row per statistic
of `pipeline.world.floor_shape.plan_statistics`, the plans' median (10th-90th percentile) beside
the generated floors'. With `--figure`, writes one PNG: the plans on the top rows, twelve generated
floors below, every tile at the same scale (free white, walls black, furniture brown, outside grey).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np

from pipeline.world.building_config import FURNITURE_LABEL, BuildingConfig
from pipeline.world.buildings import BuildingFloor, draw_building
from pipeline.world.floor_shape import STAT_CELL_M, STATISTICS, PlanGrid, plan_statistics, real_plan_grids

FIGURE_PX_PER_M = 4.0  # the figure's scale, the same for every tile
FIGURE_COLUMNS = 4
FIGURE_FLOORS = 12  # generated floors in the figure
COLOUR_FREE, COLOUR_WALL, COLOUR_FURNITURE, COLOUR_OUTSIDE = (255, 255, 255), (25, 25, 25), (60, 110, 180), (205,) * 3
WALL_REACH_CELLS = 2  # non-free cells this close to free space draw as wall, farther ones as outside


def summary(values: list[float]) -> str:
    """Median (10th-90th percentile) of the finite values, three significant digits."""
    finite = np.array([v for v in values if np.isfinite(v)], dtype=np.float64)
    if not finite.size:
        return "-"
    low, mid, high = np.percentile(finite, [10, 50, 90])
    return f"{mid:.3g} ({low:.3g}-{high:.3g})"


def table(columns: dict[str, list[dict[str, float]]]) -> str:
    """The markdown table: one row per statistic, one column per family."""
    lines = ["| statistic | " + " | ".join(columns) + " |", "|---|" + "---:|" * len(columns)]
    for key, words in STATISTICS.items():
        cells = [summary([row[key] for row in rows]) for rows in columns.values()]
        lines.append(f"| {words} | " + " | ".join(cells) + " |")
    return "\n".join(lines)


def picture(free: np.ndarray, furniture: np.ndarray | None = None) -> np.ndarray:
    """A floor as a BGR image, one pixel per cell, cropped to its free space (a margin kept) and
    turned so that its longer side runs across."""
    image = np.full(free.shape + (3,), COLOUR_OUTSIDE, np.uint8)
    near = cv2.dilate(free.astype(np.uint8), np.ones((2 * WALL_REACH_CELLS + 1,) * 2, np.uint8)).astype(bool)
    image[near & ~free] = COLOUR_WALL
    image[free] = COLOUR_FREE
    if furniture is not None:
        image[furniture] = COLOUR_FURNITURE
    rows, cols = np.nonzero(free)
    margin = WALL_REACH_CELLS + 1
    image = image[
        max(0, rows.min() - margin) : rows.max() + 1 + margin, max(0, cols.min() - margin) : cols.max() + 1 + margin
    ]
    return np.ascontiguousarray(np.rot90(image)) if image.shape[0] > image.shape[1] else image


def figure(plans: list[PlanGrid], floors: list[tuple[float, BuildingFloor]], path: str | Path) -> None:
    """The plans on the top rows and the generated floors below, FIGURE_COLUMNS a row, at one scale."""
    scale = FIGURE_PX_PER_M * STAT_CELL_M
    tiles = [(f"real: {plan.name}", picture(plan.free[::-1])) for plan in plans]  # row 0 back at the top
    split = len(tiles)
    tiles += [
        (f"generated: {side:g} m side", picture(floor.free, floor.labels == FURNITURE_LABEL)) for side, floor in floors
    ]
    tiles = [(name, cv2.resize(image, None, fx=scale, fy=scale, interpolation=cv2.INTER_AREA)) for name, image in tiles]
    width = max(image.shape[1] for _, image in tiles) + 8
    caption = 18
    rows_out = []
    for group in (tiles[:split], tiles[split:]):
        for start in range(0, len(group), FIGURE_COLUMNS):
            row_tiles = group[start : start + FIGURE_COLUMNS]
            height = max(image.shape[0] for _, image in row_tiles) + caption + 8
            row = np.full((height, width * FIGURE_COLUMNS, 3), 255, np.uint8)
            for k, (name, image) in enumerate(row_tiles):
                left = k * width + 4
                row[caption : caption + image.shape[0], left : left + image.shape[1]] = image
                cv2.putText(row, name, (left, caption - 5), cv2.FONT_HERSHEY_SIMPLEX, 0.45, (0, 0, 0), 1, cv2.LINE_AA)
            rows_out.append(row)
        rows_out.append(np.full((6, width * FIGURE_COLUMNS, 3), 150, np.uint8))  # a rule under each family
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if not cv2.imwrite(str(path), np.vstack(rows_out[:-1])):
        raise OSError(f"{path}: PNG writing failed")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--plans", default="data/real_plans/kth", help="folder of labelled plans at 0.05 m per pixel")
    parser.add_argument("--count", type=int, default=30, help="generated floors")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--side",
        type=float,
        nargs=2,
        default=(20.0, 80.0),
        metavar=("LOW", "HIGH"),
        help="generated floors' sides (m), drawn in whole metres",
    )
    parser.add_argument("--figure", default=None, help="PNG of the plans and generated floors side by side")
    args = parser.parse_args()
    plans = real_plan_grids(args.plans)
    low, high = int(np.ceil(args.side[0])), int(np.floor(args.side[1]))
    floors = []
    for i in range(args.count):
        rng = np.random.default_rng([args.seed, i])
        side = float(rng.integers(low, high + 1))
        floors.append((side, draw_building(BuildingConfig(side_m=side, cell_size=STAT_CELL_M), rng)))
    columns = {
        f"real plans ({len(plans)}, {Path(args.plans).name})": [
            plan_statistics(plan.free, plan.rooms, STAT_CELL_M) for plan in plans
        ],
        f"generated floors ({args.count}, sides {low}-{high} m)": [
            plan_statistics(floor.free, floor.room_labels, STAT_CELL_M) for _, floor in floors
        ],
    }
    print(f"{STAT_CELL_M:g} m cells; median (10th-90th percentile) over floors")
    print(table(columns))
    if args.figure:
        figure(plans, floors[:FIGURE_FLOORS], args.figure)
        print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
