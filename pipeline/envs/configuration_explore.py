"""The settings of the exploration environment (`ExploreEnv`): one frozen object, checked once.

Every value a user can pass to `gymnasium.make("guide/Explore-v0", ...)` is a field here, so
that a bad value fails when the environment is made, with a ValueError naming the parameter,
rather than deep inside an episode.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields
from os import PathLike
from typing import Any

import numpy as np

from pipeline.world.mazes import MazeConfig
from pipeline.world.protocol import Protocol

GENERATED_MAZE = "maze"  # the `map` value that draws a fresh maze at every reset
ACTION_MODES = ("neighbour", "node")
PROTOCOL_FIELDS = tuple(f.name for f in fields(Protocol))
MAX_PADDED_NODES = 32767  # neighbour lists are int16 row indices


@dataclass(frozen=True)
class ExploreEnvConfig:
    """What `ExploreEnv` runs: which maps, under which protocol, with which actions, observations
    and reward weights. Defaults are the maze benchmark's protocol and ARiADNE-style weights."""

    # --- maps
    map: str = GENERATED_MAZE  # a map file (maze .png, ROS .yaml, .npy), a folder of maps, or "maze": a new maze each reset
    start: tuple[float, float] | None = None  # start override as load_map takes it: (col, row) for .png/.npy, (x, y) m for ROS
    maze_side_m: float = 100.0  # metres: side of the generated mazes (map="maze"), a whole number of 5 m blocks
    # --- the protocol (docs/protocol.md); max_steps also bounds the environment's steps
    cell_size: float = 0.4  # metres: side of a grid cell (a ROS map brings its own)
    node_resolution: float = 4.0  # metres: spacing of the waypoint lattice
    sensor_range: float = 20.0  # metres: lidar range
    utility_range: float = 10.0  # metres: a node's frontier utility counts frontier cells this close
    region_size: float = 20.0  # metres: side of the fixed regions (kept for the protocol; the observed graph ignores it)
    done_unknown_cells: int = 250  # cells: the episode is complete when at most this many free cells are unseen
    max_steps: int = 500  # steps (actions, invalid ones too) and waypoints: the episode is truncated at either
    # --- actions and observations
    action: str = "neighbour"  # "neighbour": Discrete(25), a lattice offset in the 5x5 window; "node": a known node's row
    max_nodes: int = 320  # rows of the padded node arrays (nearest nodes first): the trained policies' size
    max_neighbors: int = 25  # neighbour slots per row (-1 padded); a lattice node has at most 24
    belief_image: bool = False  # add the belief as a uint8 image ("belief") and the robot's cell ("robot_cell")
    belief_shape: tuple[int, int] | None = None  # cells (rows, cols) of the padded belief; None: the largest map's
    # --- reward (ARiADNE-style): area_weight * new free area - distance_weight * distance + completion_bonus
    area_weight: float = 0.02  # reward per m^2 of newly observed free area (50 m^2 -> 1)
    distance_weight: float = 0.1  # penalty per metre travelled (one 4 m lattice step -> 0.4)
    completion_bonus: float = 20.0  # reward once, on the step that completes the episode
    invalid_action_penalty: float = 1.0  # penalty for a masked action (the robot stays)

    def __post_init__(self) -> None:
        if not isinstance(self.map, (str, PathLike)) or not str(self.map):
            raise ValueError(f"map must be a map file, a folder of maps or {GENERATED_MAZE!r}, got {self.map!r}")
        object.__setattr__(self, "map", str(self.map))
        if self.start is not None:
            object.__setattr__(self, "start", _pair(self.start, "start", float))
        if self.action not in ACTION_MODES:
            raise ValueError(f"action must be one of {', '.join(ACTION_MODES)}, got {self.action!r}")
        _check_int("max_steps", self.max_steps, 1)
        _check_int("max_nodes", self.max_nodes, 1, MAX_PADDED_NODES)
        _check_int("max_neighbors", self.max_neighbors, 1)
        _check_int("done_unknown_cells", self.done_unknown_cells, 0)
        for name in ("area_weight", "distance_weight", "completion_bonus", "invalid_action_penalty"):
            _check_number(name, getattr(self, name), 0.0)
        for name in ("cell_size", "node_resolution", "sensor_range", "utility_range", "region_size", "maze_side_m"):
            _check_number(name, getattr(self, name), 0.0, positive=True)
        if not isinstance(self.belief_image, bool):
            raise ValueError(f"belief_image must be true or false, got {self.belief_image!r}")
        if self.belief_shape is not None:
            shape = _pair(self.belief_shape, "belief_shape", int)
            if min(shape) < 1:
                raise ValueError(f"belief_shape must be two positive cell counts (rows, cols), got {self.belief_shape!r}")
            object.__setattr__(self, "belief_shape", shape)
        try:
            self.protocol()
        except ValueError as error:
            raise ValueError(str(error).replace("protocol.", "", 1)) from None
        if self.belief_shape is not None and not self.belief_image:
            raise ValueError("belief_shape is given but belief_image is off; add belief_image=True")
        if self.generates_mazes and self.start is not None:
            raise ValueError("start applies to map files (a generated maze has its own start); drop start or pass a map")
        if self.generates_mazes:
            try:
                self.maze_config()
            except ValueError as error:
                raise ValueError(f"maze_side_m {self.maze_side_m:g} with cell_size {self.cell_size:g}: {error}") from None

    @property
    def generates_mazes(self) -> bool:
        """Whether each reset draws a new maze rather than reading a map."""
        return self.map == GENERATED_MAZE

    def protocol(self) -> Protocol:
        """The benchmark protocol these fields make (a ROS map may still change its cell size)."""
        return Protocol(**{name: getattr(self, name) for name in PROTOCOL_FIELDS})

    def maze_config(self) -> MazeConfig:
        """The generator's settings for map="maze": the benchmark's mazes at `maze_side_m`."""
        return MazeConfig(side_m=(self.maze_side_m, self.maze_side_m), cell_size=self.cell_size)

    @classmethod
    def from_kwargs(cls, protocol: Protocol | dict[str, Any] | None = None, **values: Any) -> "ExploreEnvConfig":
        """A config from keyword values, with the protocol fields optionally given as one `Protocol`
        (or its dict); a field given by name wins over the protocol's."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(values) - known)
        if unknown:
            raise ValueError(f"unknown parameter(s) {', '.join(unknown)}; the environment takes {', '.join(sorted(known))}")
        if protocol is not None:
            if isinstance(protocol, dict):
                protocol = Protocol.from_dict(protocol)
            if not isinstance(protocol, Protocol):
                raise ValueError(f"protocol must be a Protocol or a dict of its fields, got {protocol!r}")
            values = {**protocol.to_dict(), **values}
        return cls(**values)


def _check_int(name: str, value: Any, low: int, high: int | None = None) -> None:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low or (high is not None and value > high):
        bound = f"an integer >= {low}" if high is None else f"an integer in {low}..{high}"
        raise ValueError(f"{name} must be {bound}, got {value!r}")


def _check_number(name: str, value: Any, low: float, positive: bool = False) -> None:
    ok = not isinstance(value, bool) and isinstance(value, (int, float, np.integer, np.floating)) and math.isfinite(value)
    if not ok or value < low or (positive and value <= low):
        raise ValueError(f"{name} must be a {'positive' if positive else 'non-negative'} finite number, got {value!r}")


def _pair(value: Any, name: str, kind: type) -> tuple:
    if isinstance(value, (str, bytes)) or not hasattr(value, "__len__") or len(value) != 2:
        raise ValueError(f"{name} must be a pair of numbers, got {value!r}")
    try:
        items = tuple(kind(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a pair of numbers, got {value!r}") from None
    if any(isinstance(v, bool) for v in value) or not all(math.isfinite(float(v)) for v in items):
        raise ValueError(f"{name} must be a pair of finite numbers, got {value!r}")
    if kind is int and any(float(v) != int(v) for v in value):
        raise ValueError(f"{name} must be a pair of whole numbers, got {value!r}")
    return items
