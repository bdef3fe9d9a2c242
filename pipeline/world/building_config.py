"""What kind of building floors to draw (BuildingConfig), and the labels and rectangles a drawn
floor is made of.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pipeline.world.map_files import MAX_IMAGE_PIXELS

FREE_LABEL, WALL_LABEL, FURNITURE_LABEL, OUTSIDE_LABEL = 0, 1, 2, 3


CORRIDOR = -1  # region of corridor cells (and lobbies): free space that is no room


SHAPES = ("bar", "block", "L", "T", "U", "E", "H", "cross", "ring")


Rect = tuple[int, int, int, int]  # (top, left, bottom, right) cells, bottom/right exclusive


@dataclass(frozen=True)
class BuildingConfig:
    """What kind of building floors to draw; lengths in metres, ranges inclusive.

    `side_m` is the side of the square image; the building's longer side is 85-100 % of it.
    """

    side_m: float = 40.0
    cell_size: float = 0.2
    lattice_m: float = 1.0  # the lattice the planners run on: the start lies on one of its nodes
    robot_radius_m: float = 0.2  # every free cell is reachable from the start by a robot this wide
    wall_m: tuple[float, float] = (0.1, 0.3)  # interior wall thickness, at any phase of the lattice
    outer_wall_m: tuple[float, float] = (0.2, 0.4)  # outer wall thickness
    door_m: tuple[float, float] = (0.7, 1.2)  # door width
    corridor_m: tuple[float, float] = (1.4, 2.4)  # corridor width
    room_depth_m: tuple[float, float] = (3.5, 7.0)  # a strip of rooms, corridor wall to outer wall
    core_m: tuple[float, float] = (3.0, 8.0)  # the rooms between the two corridors of a deep block
    room_width_m: tuple[float, float] = (1.8, 3.6)  # most rooms' width along their corridor
    large_room_m: tuple[float, float] = (5.0, 16.0)  # a large room's width (a lab, a lecture room)
    large_room_chance: float = 0.28
    hall_m: tuple[float, float] = (8.0, 20.0)  # a hall's length along its wing
    hall_chance: float = 0.05  # the chance the next room along a strip is a hall
    end_room_chance: float = 0.5  # the chance a corridor ends at a room across its wing, not at the outer wall
    back_room_chance: float = 0.25  # the chance a deep room is split into a front room and a back room
    second_door_chance: float = 0.05  # the chance a room gets a second door
    large_door_chance: float = 0.55  # the chance a room of more than `large_room_m2` gets a second door (a
    # quarter of it: a third)
    large_room_m2: float = 25.0
    open_room_chance: float = 0.02  # the chance a room (of at most `large_room_m2`) opens onto its corridor over
    # its whole side (a lobby)
    single_loaded_chance: float = 0.08  # the chance a wing has rooms on one side of its corridor only
    shape_weights: tuple[float, ...] = (0.55, 0.06, 0.1, 0.05, 0.07, 0.05, 0.04, 0.02, 0.06)  # per SHAPES
    aspect: tuple[float, float] = (2.5, 6.0)  # long side over short side of a shape with crossing wings ...
    min_fill: tuple[float, float] = (0.6, 0.95)  # ... lowered until its wings fill at least this share of its box
    bays: tuple[int, int] = (0, 1)  # bays (stair towers, bay rooms) out of the outer wall
    bay_m: tuple[float, float] = (1.5, 3.5)
    recesses: tuple[int, int] = (0, 3)  # recesses into the outer wall
    recess_m: tuple[float, float] = (0.6, 2.0)  # recess depth (their length is 2-8 m)
    chamfer_chance: float = 0.15  # the chance one corner of the outline is cut on the diagonal
    stub_chance: float = 0.3  # the chance a large room gets a partial wall (an L-shaped room)
    furniture: tuple[int, int] = (0, 3)  # pieces per room
    table_m: tuple[float, float] = (0.6, 1.8)  # table side
    shelf_m: tuple[float, float] = (0.3, 0.6)  # shelf depth (its length runs 1-3 m along a wall)
    column_m: tuple[float, float] = (0.3, 0.6)  # column side (halls: a row of columns)
    door_clearance_m: float = 0.6  # furniture keeps this far from every door

    def __post_init__(self) -> None:
        if not self.cell_size > 0 or not 20 <= self.side_m:
            raise ValueError(
                f"BuildingConfig needs cell_size > 0 and side_m >= 20 m, got {self.cell_size}, {self.side_m}"
            )
        for name in (
            "wall_m",
            "outer_wall_m",
            "door_m",
            "corridor_m",
            "room_depth_m",
            "core_m",
            "room_width_m",
            "large_room_m",
            "hall_m",
            "aspect",
            "min_fill",
            "bays",
            "bay_m",
            "recesses",
            "recess_m",
            "furniture",
            "table_m",
            "shelf_m",
            "column_m",
        ):
            low, high = getattr(self, name)
            if not 0 <= low <= high:
                raise ValueError(
                    f"BuildingConfig.{name} must be a range low <= high of non-negative values, got {(low, high)}"
                )
        step = self.lattice_m / self.cell_size
        if not (step >= 2 and abs(step - round(step)) < 1e-9):
            raise ValueError(
                f"BuildingConfig.lattice_m ({self.lattice_m:g} m) must be a whole number (2 or more) of "
                f"cells ({self.cell_size:g} m): the start is placed on its nodes"
            )
        if self.cells(self.door_m[0]) < 2:
            raise ValueError(f"BuildingConfig.door_m must start at two cells or more, got {self.door_m}")
        if self.door_m[1] + 0.4 > self.room_width_m[0] or self.room_depth_m[0] < 2 * self.door_m[1]:
            raise ValueError(
                "BuildingConfig.room_width_m must start 0.4 m above the widest door and room_depth_m "
                "at twice it, so that every room has a wall a door fits in"
            )
        if len(self.shape_weights) != len(SHAPES) or min(self.shape_weights) < 0 or sum(self.shape_weights) <= 0:
            raise ValueError(f"BuildingConfig.shape_weights needs one non-negative weight per shape {SHAPES}")
        if self.aspect[0] < 1:
            raise ValueError(f"BuildingConfig.aspect is long side over short side, 1 or more, got {self.aspect}")
        if (2 * self.cells(self.side_m)) ** 2 > MAX_IMAGE_PIXELS:
            largest = math.isqrt(MAX_IMAGE_PIXELS) // 2 * self.cell_size
            raise ValueError(
                f"building floors of {self.side_m:g} m make an image of more than the map loader reads; "
                f"the largest side at {self.cell_size:g} m cells is {largest:.0f} m"
            )

    def cells(self, metres: float) -> int:
        """A length in whole cells (at least one)."""
        return max(1, int(round(metres / self.cell_size)))
