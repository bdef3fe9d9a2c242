"""The benchmark protocol's values (docs/protocol.md), one frozen object passed everywhere."""

from __future__ import annotations

import math
from dataclasses import asdict, fields, replace
from pathlib import Path
from typing import Annotated, Any

from pipeline.common.config import config_dataclass, flag, maybe, positive, real, validate, whole
from pipeline.world.map_files import MapError
from pipeline.world.maps import GroundTruthMap

DOOR_GRAPH_BELOW_M = 2.0  # lattice spacings under this are the building scale (`Protocol.uses_door_graph`)


@config_dataclass
class Protocol:
    """Every protocol value is a parameter; the defaults are the maze benchmark's. NaN and
    infinities are refused here, not deep in a ray table."""

    cell_size: Annotated[float, positive("metres per grid cell")] = 0.4
    node_resolution: Annotated[float, positive("lattice spacing in metres")] = 4.0
    sensor_range: Annotated[float, positive("metres")] = 20.0
    utility_range: Annotated[float, positive("metres")] = 10.0
    region_size: Annotated[float, positive("metres")] = 20.0
    done_unknown_cells: Annotated[int, whole(0, note="cells")] = 250
    max_steps: Annotated[int, whole(1, note="waypoints")] = 500
    robot_radius_m: Annotated[
        float, real(0.0, note="metres: what fits through a door, for the door-aware graph and the done rule")
    ] = 0.2
    door_graph: Annotated[bool | None, maybe(flag(), "on below a 2 m lattice, the building scale")] = None

    def __post_init__(self) -> None:
        if self.node_resolution < self.cell_size:
            raise ValueError(
                f"node_resolution ({self.node_resolution:g} m) must be at least one cell ({self.cell_size:g} m)"
            )

    @property
    def uses_door_graph(self) -> bool:
        """Whether waypoints may be door nodes and "done" is checked on cells (docs/protocol.md, "The
        whole building"): `door_graph` when set, else on below a `DOOR_GRAPH_BELOW_M` lattice. The maze
        benchmark's 4 m lattice passes every maze door (a 5 m block) with a straight edge, so it keeps
        DARE's lattice exactly; a building's doors (0.6-1.2 m) are narrower than a 1 m lattice's
        edges are reliable for."""
        return self.door_graph if self.door_graph is not None else self.node_resolution < DOOR_GRAPH_BELOW_M

    @property
    def robot_radius_cells(self) -> float:
        return self.robot_radius_m / self.cell_size

    @property
    def sensor_range_cells(self) -> float:
        return self.sensor_range / self.cell_size

    def with_cell_size(self, cell_size: float) -> "Protocol":
        """The same protocol on a map with its own cell size (a ROS map's resolution)."""
        return replace(self, cell_size=cell_size)

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None) -> "Protocol":
        """The protocol a mapping names (a params.yaml `protocol` section, a model's record; None: the defaults); a refused
        value is a ValueError naming it as `protocol.key`."""
        return validate(cls, values, "protocol")


class ProtocolMismatchWarning(UserWarning):
    """A trained model runs at other protocol values than it was trained at (it still runs)."""


# What a learned model's inputs depend on: the lattice the node images and graphs are drawn on, how far
# the sensor reveals cells and how far the utility counts frontier cells. (The cell size does not: a node
# image holds one pixel per lattice node, whatever the cells, so a ROS map at its own resolution is fine.)
MODEL_INPUT_FIELDS = ("node_resolution", "sensor_range", "utility_range", "region_size")


def model_input_differences(trained: dict[str, Any] | None, protocol: Protocol) -> list[str]:
    """The protocol values a model was trained at that `protocol` changes, as "name a -> b" strings.

    `trained` is the protocol recorded with the model (`Protocol.to_dict()`); None (models exported
    before it was recorded, the shipped ones included) stands for the defaults they were trained at.
    """
    known = {f.name for f in fields(Protocol)}
    # Only the fields this version knows: an export from a later version may record more.
    reference = Protocol.from_dict({k: v for k, v in (trained or {}).items() if k in known})
    return [
        f"{name} {getattr(reference, name):g} -> {getattr(protocol, name):g}"
        for name in MODEL_INPUT_FIELDS
        if not math.isclose(getattr(reference, name), getattr(protocol, name), rel_tol=1e-9)
    ]


PAPER_REAL_ROBOT = Protocol(
    cell_size=0.2,
    node_resolution=1.0,
    sensor_range=10.0,
    utility_range=5.0,
    region_size=10.0,
    done_unknown_cells=1000,
    max_steps=2000,
)
"""The paper's real-robot setting (0.2 m cells, 1 m nodes, 10 m sensor) as profiles/real_robot.yaml
runs it: regions as wide as the sensor reaches, done at 40 m^2 unseen."""

PROTOCOLS = {"maze": Protocol(), "real_robot": PAPER_REAL_ROBOT}  # the shipped profiles' protocols, by name


def protocol_for_map(protocol: Protocol, ground_truth: GroundTruthMap, source: str | Path | None = None) -> Protocol:
    """A ROS map carries its own cell size; every other protocol value stays.

    MapError (naming `source`, the map's file, else its name) for a map with no more free cells
    than `done_unknown_cells`: every episode on it would count as complete at 0 m (e.g. a PNG
    whose free space is drawn in a colour read as wall).
    """
    where = source if source is not None else ground_truth.name
    if ground_truth.free_cell_count <= protocol.done_unknown_cells:
        raise MapError(
            where,
            f"only {ground_truth.free_cell_count} free cells, not more than done_unknown_cells="
            f"{protocol.done_unknown_cells}: an episode would be complete before the robot moves"
            + (f" ({ground_truth.free_rule})" if ground_truth.free_rule else ""),
        )
    if abs(ground_truth.cell_size - protocol.cell_size) > 1e-12:
        protocol = protocol.with_cell_size(ground_truth.cell_size)
    rows, cols = ground_truth.free.shape
    diagonal_m = math.hypot(rows, cols) * protocol.cell_size
    if (
        protocol.sensor_range > 2 * diagonal_m
    ):  # a ray table that long costs minutes and gigabytes, and sees nothing more
        raise MapError(
            where,
            f"sensor range {protocol.sensor_range:g} m is more than twice the map's diagonal ({diagonal_m:.1f} m); "
            "a longer lidar sees nothing more: use a shorter --sensor-range",
        )
    return protocol
