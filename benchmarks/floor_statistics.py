"""What decides what an inpainter learns from a map family, measured on generated floors.

Usage: python benchmarks/floor_statistics.py [--count 200] [--seed 0] [--figure docs/buildings.png]

Draws `--count` building floors (`pipeline.world.buildings`, sides 20-80 m) and as many
real-robot office floors (`pipeline.world.offices`, sides 20-60 m) at 0.2 m cells and a 1 m
lattice, and prints per family: the share of interior wall runs that cover a lattice node, the
share of the lattice nodes inside the outline on walls and on furniture, the free share, the
mean door width and the median room area (mean over floors, with the 10th-90th percentile).
With `--figure`, writes 16 building floors in a 4 x 4 grid (walls black, furniture brown,
outside grey, the start red).
"""

from __future__ import annotations

import argparse

import cv2
import numpy as np

from pipeline.world.buildings import (
    FREE_LABEL,
    FURNITURE_LABEL,
    OUTSIDE_LABEL,
    WALL_LABEL,
    BuildingConfig,
    BuildingFloor,
    draw_building,
    floor_statistics,
)
from pipeline.world.offices import OfficeConfig, draw_office

COLOURS_BGR = {FREE_LABEL: (255, 255, 255), WALL_LABEL: (30, 30, 30), FURNITURE_LABEL: (60, 110, 180),
               OUTSIDE_LABEL: (200, 200, 200)}
KEYS = ("wall_runs_on_nodes", "nodes_on_walls", "nodes_on_furniture", "free_share", "door_m", "room_m2")


def office_as_floor(side: float, rng: np.random.Generator) -> BuildingFloor:
    """A real-robot office floor in the building floors' terms (its walls found as the non-free
    cells inside its outer ring; its rooms and doors are not kept, so those two stay unmeasured)."""
    config = OfficeConfig.real_robot(side_m=side)
    free, start = draw_office(config, rng)
    labels = np.where(free, FREE_LABEL, WALL_LABEL).astype(np.uint8)
    labels[:2], labels[-2:], labels[:, :2], labels[:, -2:] = OUTSIDE_LABEL, OUTSIDE_LABEL, OUTSIDE_LABEL, OUTSIDE_LABEL
    step = config.cells(config.lattice_m)
    return BuildingFloor(labels, start, step, (start[0] % step, start[1] % step), (), (), ())


def summarise(rows: list[dict[str, float]], keys: tuple[str, ...]) -> dict[str, str]:
    out = {}
    for key in keys:
        values = np.array([row[key] for row in rows], dtype=np.float64)
        values = values[np.isfinite(values)]
        out[key] = (f"{values.mean():.3g} ({np.percentile(values, 10):.3g}-{np.percentile(values, 90):.3g})"
                    if values.size else "-")
    return out


def tile(floor: BuildingFloor, size: int = 400) -> np.ndarray:
    image = np.zeros(floor.labels.shape + (3,), np.uint8)
    for label, colour in COLOURS_BGR.items():
        image[floor.labels == label] = colour
    row, col = floor.start
    image[row - 3 : row + 4, col - 3 : col + 4] = (0, 0, 230)
    return cv2.resize(image, (size, size), interpolation=cv2.INTER_NEAREST)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--count", type=int, default=200)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--figure", default=None, help="PNG of 16 building floors")
    args = parser.parse_args()
    buildings, offices = [], []
    for i in range(args.count):
        rng = np.random.default_rng([args.seed, i])
        side = float(rng.integers(20, 81))
        buildings.append(draw_building(BuildingConfig(side_m=side), rng))
        offices.append(office_as_floor(float(rng.integers(20, 61)), rng))
    rows = {"building floors": [floor_statistics(f, 0.2) for f in buildings],
            "office floors (real_robot)": [floor_statistics(f, 0.2) for f in offices]}
    print(f"{args.count} floors per family, 0.2 m cells, 1 m lattice; mean (10th-90th percentile)")
    print("| family | " + " | ".join(KEYS) + " |")
    print("|---|" + "---:|" * len(KEYS))
    for family, family_rows in rows.items():
        keys = KEYS if family.startswith("building") else KEYS[1:4]
        cells = summarise(family_rows, keys)
        print(f"| {family} | " + " | ".join(cells.get(key, "-") for key in KEYS) + " |")
    if args.figure:
        tiles = [tile(floor) for floor in buildings[:16]]
        gap = np.full((400, 8, 3), 255, np.uint8)
        rows_img = [np.hstack([t for k in range(4) for t in (tiles[4 * r + k], gap)][:-1]) for r in range(4)]
        hgap = np.full((8, rows_img[0].shape[1], 3), 255, np.uint8)
        grid = np.vstack([x for r in rows_img for x in (r, hgap)][:-1])
        cv2.imwrite(args.figure, grid)
        print(f"wrote {args.figure}")


if __name__ == "__main__":
    main()
