"""The settings of the exploration environment (`ExploreEnv`): one frozen object, checked once.

Every value a user can pass to `gymnasium.make("guide/Explore-v0", ...)` is a field here, typed with
`pipeline.common.config`'s constrained types, so that a bad value fails when the environment is
made, with a one-line ValueError naming the parameter (`max_steps: must be a whole number >= 1,
got 0`), rather than deep inside an episode.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import fields
from typing import Annotated, Any, Self

from pydantic import AfterValidator, BeforeValidator

from pipeline.common.config import (
    Rule,
    config_dataclass,
    flag,
    list_of,
    maybe,
    positive,
    real,
    satisfies,
    text,
    validate,
    whole,
)
from pipeline.world.mazes import MazeConfig
from pipeline.world.protocol import Protocol

GENERATED_MAZE = "maze"  # the `map` value that draws a fresh maze at every reset
ACTION_MODES = ("neighbour", "node")
# The protocol's fields the environment takes: all but the door-aware graph's switch, since its
# actions are lattice moves and it keeps DARE's lattice of straight edges at every scale.
PROTOCOL_FIELDS = tuple(f.name for f in fields(Protocol) if f.name != "door_graph")
MAX_PADDED_NODES = 32767  # neighbour lists are int16 row indices


def _path_text(value: Any) -> Any:
    """A path object as its text (a `pathlib.Path` names a map as well as a string does)."""
    return os.fspath(value) if isinstance(value, os.PathLike) else value


def _as_tuple(value: Any) -> Any:
    """Any sequence (a list, a numpy array) as a tuple, for the pairs below."""
    if hasattr(value, "__len__") and not isinstance(value, (str, bytes, Mapping)):
        return tuple(value)
    return value


def _two(values: list) -> None:
    if len(values) != 2:
        raise ValueError(f"{len(values)} values")


def _pair_of(item: Any, what: str) -> Rule:
    """Two values of type `item` (a tuple, a list or an array of them), kept as a tuple."""
    two = satisfies(_two, what, list_of(item, 2, description=what))
    return Rule(Annotated[two.type, BeforeValidator(_as_tuple), AfterValidator(tuple)])


MapName = Annotated[str, text(note=f"a map file, a folder of maps or {GENERATED_MAZE!r}"), BeforeValidator(_path_text)]


@config_dataclass
class ExploreEnvConfig:
    """What `ExploreEnv` runs: which maps, under which protocol, with which actions, observations
    and reward weights. Defaults are the maze benchmark's protocol and ARiADNE-style weights."""

    # --- maps
    map: MapName = (
        GENERATED_MAZE  # a map file (maze .png, ROS .yaml, .npy), a folder of maps, or "maze": a new maze each reset
    )
    # start override as load_map takes it: (col, row) for .png/.npy, (x, y) m for ROS
    start: Annotated[list[float] | None, maybe(_pair_of(real(), "a pair of finite numbers"), "the map's")] = None
    maze_side_m: Annotated[float, positive("metres")] = (
        100.0  # side of the generated mazes (map="maze"), a whole number of 5 m blocks
    )
    # --- the protocol (docs/protocol.md); max_steps also bounds the environment's steps
    cell_size: Annotated[float, positive("metres")] = 0.4  # side of a grid cell (a ROS map brings its own)
    node_resolution: Annotated[float, positive("metres")] = 4.0  # spacing of the waypoint lattice
    sensor_range: Annotated[float, positive("metres")] = 20.0  # lidar range
    utility_range: Annotated[float, positive("metres")] = (
        10.0  # a node's frontier utility counts frontier cells this close
    )
    region_size: Annotated[float, positive("metres")] = (
        20.0  # side of the fixed regions (kept for the protocol; the observed graph ignores it)
    )
    done_unknown_cells: Annotated[int, whole(0, note="cells")] = (
        250  # the episode is complete when at most this many free cells are unseen
    )
    max_steps: Annotated[int, whole(1)] = (
        500  # steps (actions, invalid ones too) and waypoints: the episode is truncated at either
    )
    robot_radius_m: Annotated[float, real(0.0)] = (
        0.2  # metres: what fits through a door (the protocol's; unused on the lattice)
    )
    # --- actions and observations
    action: Annotated[str, text(ACTION_MODES)] = (
        "neighbour"  # "neighbour": Discrete(25), a lattice offset in the 5x5 window; "node": a known node's row
    )
    max_nodes: Annotated[int, whole(1, MAX_PADDED_NODES)] = (
        320  # rows of the padded node arrays (nearest nodes first): the trained policies' size
    )
    max_neighbors: Annotated[int, whole(1)] = 25  # neighbour slots per row (-1 padded); a lattice node has at most 24
    belief_image: Annotated[bool, flag()] = (
        False  # add the belief as a uint8 image ("belief") and the robot's cell ("robot_cell")
    )
    belief_shape: Annotated[
        list[int] | None, maybe(_pair_of(whole(1), "two cell counts (rows, cols)"), "the largest map's")
    ] = None  # cells (rows, cols) of the padded belief
    # --- reward (ARiADNE-style): area_weight * new free area - distance_weight * distance + completion_bonus
    area_weight: Annotated[float, real(0.0)] = 0.02  # reward per m^2 of newly observed free area (50 m^2 -> 1)
    distance_weight: Annotated[float, real(0.0)] = 0.1  # penalty per metre travelled (one 4 m lattice step -> 0.4)
    completion_bonus: Annotated[float, real(0.0)] = 20.0  # reward once, on the step that completes the episode
    invalid_action_penalty: Annotated[float, real(0.0)] = 1.0  # penalty for a masked action (the robot stays)

    def __post_init__(self) -> None:
        # Each value alone is checked by its type; these are the rules between values.
        validate(Protocol, {name: getattr(self, name) for name in PROTOCOL_FIELDS})
        if self.belief_shape is not None and not self.belief_image:
            raise ValueError("belief_shape is given but belief_image is off; add belief_image=True")
        if self.generates_mazes and self.start is not None:
            raise ValueError(
                "start applies to map files (a generated maze has its own start); drop start or pass a map"
            )
        if self.generates_mazes:
            try:
                self.maze_config()
            except ValueError as error:  # the generator's own refusal
                raise ValueError(
                    f"maze_side_m {self.maze_side_m:g} with cell_size {self.cell_size:g}: {error}"
                ) from None

    @property
    def generates_mazes(self) -> bool:
        """Whether each reset draws a new maze rather than reading a map."""
        return self.map == GENERATED_MAZE

    def protocol(self) -> Protocol:
        """The benchmark protocol these fields make (a ROS map may still change its cell size)."""
        return Protocol(**{name: getattr(self, name) for name in PROTOCOL_FIELDS}, door_graph=False)

    def maze_config(self) -> MazeConfig:
        """The generator's settings for map="maze": the benchmark's mazes at `maze_side_m`."""
        return MazeConfig(side_m=(self.maze_side_m, self.maze_side_m), cell_size=self.cell_size)

    @classmethod
    def from_kwargs(cls, protocol: Protocol | dict[str, Any] | None = None, **values: Any) -> Self:
        """A config from keyword values, with the protocol fields optionally given as one `Protocol`
        (or its dict); a field given by name wins over the protocol's."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(
                f"unknown parameter(s) {', '.join(unknown)}; the environment takes {', '.join(sorted(known))}"
            )
        if protocol is not None:
            if isinstance(protocol, dict):
                protocol = Protocol.from_dict(protocol)
            if not isinstance(protocol, Protocol):
                raise ValueError(f"protocol must be a Protocol or a dict of its fields, got {protocol!r}")
            values = {**{k: v for k, v in protocol.to_dict().items() if k in PROTOCOL_FIELDS}, **values}
        return validate(cls, values)
