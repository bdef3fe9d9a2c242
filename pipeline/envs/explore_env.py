"""`guide/Explore-v0`: a Gymnasium environment over the exploration simulator (docs/environment.md).

The agent chooses the robot's next lattice node; the simulator (`Episode.move`) moves it there
and senses, and stays the referee of the protocol's motion and done rules. The observation is
the observed graph as the learned planners see it (`pipeline/prediction/observed_graph.py`), with the action mask
as one of its keys; the reward is ARiADNE's kind: newly observed free area, minus distance,
plus a bonus on completion.

The environment keeps its own lattice graph, updated with the belief cells each step changed
(found by comparing the belief near the cells the robot sensed from), so that
`env.unwrapped.episode.observe()` stays the agent's: a planner driving the environment gets
every change since its last observation, exactly as under `run_episode`.
"""

from __future__ import annotations

import copy
from typing import Any, Sequence, cast

import gymnasium
import numpy as np
from gymnasium import spaces

from pipeline.envs.configuration_explore import ExploreEnvConfig
from pipeline.envs.map_sources import DrawnMap, map_source
from pipeline.lattice.graph import LatticeGraph
from pipeline.lattice.spec import LatticeSpec
from pipeline.prediction.global_graph import FEATURE_NAMES, GlobalGraphConfig
from pipeline.prediction.observed_graph import (
    SLOT_OFFSETS,
    SLOTS,
    STAY_SLOT,
    ObservedStep,
    WindowTable,
    observe_lattice,
    slot_of_offset,
    window_moves,
)
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import OCCUPIED
from pipeline.world.simulator import Episode

#: Lattice graphs kept per map file, ready to copy at a reset (their geometry takes a while to lay out).
LATTICE_CACHE_SIZE = 4


def graph_observation(view: ObservedStep, mask: np.ndarray) -> dict[str, Any]:
    """The observed-graph keys of an observation and the action mask, as fresh arrays (a step that
    leaves the robot where it was returns the same values)."""
    return {
        "features": view.features.copy(),
        "node_mask": view.node_mask.astype(np.int8),
        "neighbors": view.neighbors.copy(),
        "robot": np.int64(view.robot_row),
        "action_mask": mask.copy(),
    }


def waypoint_action(
    action: str, lattice: LatticeGraph, view: ObservedStep, position: Sequence[float], waypoint, rows_of: str
) -> int:
    """The action of mode `action` that moves a robot at `position` to a lattice waypoint (metres):
    its slot in neighbour mode, its row of `view` in node mode; ValueError when it has none."""
    d = lattice.spec.node_resolution
    i, j = int(round(float(waypoint[0]) / d)), int(round(float(waypoint[1]) / d))
    if action == "neighbour":
        return slot_of_offset(i - int(round(position[0] / d)), j - int(round(position[1] / d)))
    node = lattice.node_id(i, j)
    rows: np.ndarray | list[int] = np.flatnonzero(view.row_nodes == node) if node >= 0 else []
    if len(rows) == 0:
        raise ValueError(f"waypoint {tuple(waypoint)} is not a known node among {rows_of}'s rows")
    return int(rows[0])


def reward_info(area: float, distance: float, parts: tuple[float, float, float, float]) -> dict[str, float]:
    """An info's account of a step's reward: the new free area (m^2), the distance moved (m), and
    the reward's four terms (area, distance, completion bonus, invalid-action penalty)."""
    keys = ("reward_area", "reward_distance", "reward_bonus", "reward_invalid")
    return {"new_area_m2": area, "step_distance_m": distance, **dict(zip(keys, parts))}


class LatticeCache:
    """Empty lattice graphs of the last `size` map files with their window tables: a reset copies
    one instead of laying it out anew; a generated maze (never seen again) gets a fresh one."""

    def __init__(self, size: int = LATTICE_CACHE_SIZE):
        self.size = size
        self.kept: dict[str, tuple[LatticeGraph, WindowTable]] = {}

    def fresh(self, drawn: DrawnMap) -> tuple[LatticeGraph, WindowTable]:
        """An empty lattice graph of the drawn map and its window table."""
        if not drawn.key:
            graph = LatticeGraph(LatticeSpec.for_map(drawn.ground_truth, drawn.protocol))
            return graph, WindowTable(graph)
        if drawn.key not in self.kept:
            if len(self.kept) >= self.size:
                self.kept.pop(next(iter(self.kept)))
            graph = LatticeGraph(LatticeSpec.for_map(drawn.ground_truth, drawn.protocol))
            self.kept[drawn.key] = (graph, WindowTable(graph))
        template, table = self.kept[drawn.key]
        return copy.deepcopy(template), table


def checked_action(action: Any, count: int) -> int:
    """A discrete action as an int in 0..count-1 (a 0-d array accepted); ValueError otherwise."""
    if isinstance(action, np.ndarray) and action.shape == ():
        action = action.item()
    if isinstance(action, (bool, np.bool_)) or not isinstance(action, (int, np.integer)):
        raise ValueError(f"action must be an integer in 0..{count - 1}, got {action!r}")
    if not 0 <= action < count:
        raise ValueError(f"action {action} lies outside 0..{count - 1}")
    return int(action)


class ExploreEnv(gymnasium.Env):
    """Explore an unknown map with a lidar by choosing lattice nodes; see docs/environment.md.

    `ExploreEnv(map="maze", action="neighbour", ...)` takes `ExploreEnvConfig`'s fields as keywords
    (or `config=`), and `protocol=` a `Protocol` (or its dict) for the protocol fields at once.
    """

    metadata = {"render_modes": ["rgb_array"], "render_fps": 4}

    def __init__(
        self,
        config: ExploreEnvConfig | None = None,
        render_mode: str | None = None,
        protocol: Protocol | dict | None = None,
        **values: Any,
    ):
        if config is not None and (values or protocol is not None):
            raise ValueError("pass either config= or keyword parameters, not both")
        self.config = config if config is not None else ExploreEnvConfig.from_kwargs(protocol, **values)
        if render_mode is not None and render_mode not in self.metadata["render_modes"]:
            raise ValueError(f"render_mode must be None or one of {self.metadata['render_modes']}, got {render_mode!r}")
        self.render_mode = render_mode
        cfg = self.config
        start = cast(tuple[float, float] | None, cfg.start)  # a pair, (col, row) or (x, y) m
        self.source = map_source(cfg.map, start, cfg.protocol(), cfg.maze_config() if cfg.generates_mazes else None)
        self.graph_config = GlobalGraphConfig(max_nodes=cfg.max_nodes, use_region_evaluation=False)
        self.action_count = SLOTS if cfg.action == "neighbour" else cfg.max_nodes
        self.action_space = spaces.Discrete(self.action_count)
        self.belief_shape: Sequence[int] | None = None  # (rows, cols)
        if cfg.belief_image:
            self.belief_shape = cfg.belief_shape or self.source.largest_shape()
        self.observation_space = self._observation_space()
        self._lattices = LatticeCache()
        self._episode: Episode | None = None
        self._view: ObservedStep | None = None  # the last observation's arrays and search
        self._over = True

    # ------------------------------------------------------------------ spaces
    def _observation_space(self) -> spaces.Dict:
        n, m = self.config.max_nodes, self.config.max_neighbors
        low = np.zeros((n, len(FEATURE_NAMES)), dtype=np.float32)
        high = np.ones((n, len(FEATURE_NAMES)), dtype=np.float32)
        low[:, 0:2], high[:, 0:2] = -self._row_reach(), self._row_reach()
        keys: dict[str, spaces.Space] = {
            "features": spaces.Box(low, high, dtype=np.float32),
            "node_mask": spaces.MultiBinary(n),
            "neighbors": spaces.Box(-1, n - 1, (n, m), dtype=np.int16),
            "robot": spaces.Discrete(n),
            "action_mask": spaces.MultiBinary(self.action_count),
        }
        if self.belief_shape is not None:
            keys["belief"] = spaces.Box(0, 255, self.belief_shape, dtype=np.uint8)
            keys["robot_cell"] = spaces.Box(0, max(self.belief_shape) - 1, (2,), dtype=np.int64)
        return spaces.Dict(keys)

    def _row_reach(self) -> float:
        """How far (in dx, dy units) a row's node can lie from the robot, whatever the map: every known
        node was seen from the robot's component of the known graph (within the sensor's range and a
        cell), whose edges span at most two node spacings along each axis; so at least
        min(max_nodes, component size) nodes lie within (max_nodes - 1) such edges."""
        cfg, d = self.config, self.config.node_resolution
        metres = (cfg.max_nodes - 1) * 2 * np.sqrt(2.0) * d + cfg.sensor_range + d
        return float(np.ceil(metres / (self.graph_config.position_scale_nodes * d)))

    # ------------------------------------------------------------------ read-only views
    @property
    def episode(self) -> Episode:
        """The simulator's episode (read-only: never move it). `episode.observe()` is the agent's own:
        the environment never calls it, so a planner sees every change since its last call."""
        if self._episode is None:
            raise RuntimeError("reset() the environment first")
        return self._episode

    @property
    def ground_truth(self):
        """The map of the current episode (what a baseline would be run on to compare)."""
        if self._episode is None:
            raise RuntimeError("reset() the environment first")
        return self._drawn.ground_truth

    @property
    def lattice(self) -> LatticeGraph:
        """The environment's lattice graph, up to date with the belief (read-only)."""
        return self._lattice

    @property
    def visited(self) -> np.ndarray:
        """Per lattice node, whether the robot has stood on it (read-only): the `visited` feature."""
        return self._visited

    @property
    def row_nodes(self) -> np.ndarray:
        """The lattice node id of each filled row of the last observation, nearest the robot first."""
        return cast(ObservedStep, self._view).row_nodes

    def action_masks(self) -> np.ndarray:
        """Which actions are valid now (sb3-contrib's MaskablePPO asks for this)."""
        if self._episode is None:
            raise RuntimeError("reset() the environment first")
        return self._mask.astype(bool)

    def action_for_waypoint(self, waypoint) -> int:
        """The action that moves the robot to a lattice waypoint (metres): its slot in neighbour mode
        (the waypoint must lie in the robot's 5 x 5 window), its row in node mode. ValueError when
        the waypoint has no action (off the lattice, out of the window, not among the rows)."""
        view = cast(ObservedStep, self._view)
        return waypoint_action(
            self.config.action, self._lattice, view, self.episode.position, waypoint, "the observation"
        )

    # ------------------------------------------------------------------ episode
    def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None):
        super().reset(seed=seed)
        drawn = self.source.draw(self.np_random)
        self._drawn, self._protocol = drawn, drawn.protocol
        self._episode = Episode(drawn.ground_truth, drawn.protocol)
        self._lattice, self._table = self._lattices.fresh(drawn)
        self._visited = np.zeros(self._lattice.node_count, dtype=bool)
        belief = self._episode.belief.grid
        self._lattice.update(belief, None)
        self._seen = belief.copy()  # the belief the lattice graph reflects
        self._steps, self._over = 0, False
        self._visited[self._lattice.nearest_node(self._episode.position)] = True
        self._observe()
        return self._observation(), self._info(
            invalid=False, stuck=False, parts=(0.0, 0.0, 0.0, 0.0), area=0.0, distance=0.0
        )

    def step(self, action):
        if self._episode is None or self._over:
            raise RuntimeError("the episode is over (or never began): call reset()")
        slot = checked_action(action, self.action_count)
        episode, cfg = self._episode, self.config
        free_before, distance_before, was_complete = episode.belief.free_count, episode.distance, episode.complete
        self._steps += 1
        invalid = not self._mask[slot]
        stuck = not invalid and self._no_move
        if not invalid and not stuck:
            sensed = [episode.cell]
            for node in self._path(slot):
                episode.move(tuple(map(float, self._lattice.node_world[node])))
                sensed.append(episode.cell)
                self._visited[node] = True
                if episode.complete or episode.steps >= self._protocol.max_steps:
                    break
            self._fold_changes(sensed)
            self._observe()
        area = (episode.belief.free_count - free_before) * self._protocol.cell_size**2
        distance = episode.distance - distance_before
        parts = (
            cfg.area_weight * area,
            -cfg.distance_weight * distance,
            cfg.completion_bonus if episode.complete and not was_complete else 0.0,
            -cfg.invalid_action_penalty if invalid else 0.0,
        )
        terminated = episode.complete or stuck
        truncated = not terminated and (self._steps >= cfg.max_steps or episode.steps >= self._protocol.max_steps)
        self._over = terminated or truncated
        info = self._info(invalid=invalid, stuck=stuck, parts=parts, area=area, distance=distance)
        return self._observation(), float(sum(parts)), bool(terminated), bool(truncated), info

    def _path(self, action: int) -> list[int]:
        """The lattice nodes a valid action moves the robot through, in order (its own node not included):
        the neighbour in the action's slot, or the shortest known path to the action's row."""
        view = cast(ObservedStep, self._view)
        if self.config.action == "neighbour":
            return [int(self._table.neighbour[view.robot_node, action])]
        return self._lattice.path_from_predecessors(view.predecessors, int(view.row_nodes[action]))[1:]

    def _fold_changes(self, sensed: list[tuple[int, int]]) -> None:
        """Update the lattice graph with the belief cells changed by scans from the `sensed` cells:
        a scan changes cells only within the sensor's reach of where it was taken."""
        belief, seen = cast(Episode, self._episode).belief.grid, self._seen
        reach = int(np.ceil(self._protocol.sensor_range_cells)) + 1
        cells = np.asarray(sensed)
        rows, cols = belief.shape
        x0, x1 = max(0, cells[:, 0].min() - reach), min(cols, cells[:, 0].max() + reach + 1)
        y0, y1 = max(0, cells[:, 1].min() - reach), min(rows, cells[:, 1].max() + reach + 1)
        window = belief[y0:y1, x0:x1]
        dy, dx = np.divmod(np.flatnonzero(window != seen[y0:y1, x0:x1]), x1 - x0)
        seen[y0:y1, x0:x1] = window
        self._lattice.update(belief, (dy + y0) * cols + (dx + x0))

    def _observe(self) -> None:
        """Build the observation of the current state and the action mask."""
        view = observe_lattice(
            self._lattice,
            self._table,
            cast(Episode, self._episode).position,
            self._visited,
            self.graph_config,
            self.config.max_neighbors,
        )
        self._view = view
        mask = np.zeros(self.action_count, dtype=np.int8)
        if self.config.action == "neighbour":
            mask[:] = window_moves(self._lattice, self._table, view.robot_node)
            self._stay = STAY_SLOT
        else:
            filled = len(view.row_nodes)
            mask[:filled] = np.isfinite(view.distance[view.row_nodes]) & (view.row_nodes != view.robot_node)
            self._stay = view.robot_row
        self._no_move = not mask.any()
        if self._no_move:  # staying, which ends the episode, is then the one valid action
            mask[self._stay] = 1
        self._mask = mask

    def _observation(self) -> dict[str, Any]:
        obs = graph_observation(cast(ObservedStep, self._view), self._mask)
        if self.belief_shape is not None:
            obs["belief"] = self._padded_belief()
            col, row = cast(Episode, self._episode).cell
            obs["robot_cell"] = np.array([col, row], dtype=np.int64)
        return obs

    def _padded_belief(self) -> np.ndarray:
        """The belief in the top-left corner of a `belief_shape` image; cells beyond the map read OCCUPIED."""
        grid = cast(Episode, self._episode).belief.grid
        rows, cols = grid.shape
        shape = cast(Sequence[int], self.belief_shape)
        if rows > shape[0] or cols > shape[1]:
            raise ValueError(
                f"belief_shape {self.belief_shape} is smaller than map {self._drawn.ground_truth.name}'s "
                f"grid {grid.shape}; pass a larger belief_shape"
            )
        image = np.full(shape, OCCUPIED, dtype=np.uint8)
        image[:rows, :cols] = grid
        return image

    def _info(
        self, invalid: bool, stuck: bool, parts: tuple[float, float, float, float], area: float, distance: float
    ) -> dict[str, Any]:
        episode = cast(Episode, self._episode)
        return {
            "map_name": self._drawn.ground_truth.name,
            "steps": self._steps,
            "waypoints": episode.steps,
            "distance": episode.distance,
            "explored_share": episode.explored_ratio,
            "complete": episode.complete,
            "trajectory": list(episode.trajectory),
            "invalid_action": invalid,
            "stuck": stuck,
            **reward_info(area, distance, parts),
        }

    # ------------------------------------------------------------------ render
    def render(self) -> np.ndarray | None:
        """rgb_array: the belief (white free, grey unknown, black occupied), the path in blue, the robot in red."""
        if self.render_mode != "rgb_array" or self._episode is None:
            return None
        image = np.repeat(self._episode.belief.grid[:, :, None], 3, axis=2)  # FREE 255, UNKNOWN 128, OCCUPIED 0
        cell, start = self._protocol.cell_size, self._drawn.ground_truth.start_cell
        for x, y in self._episode.trajectory:
            col, row = start[0] + int(round(x / cell)), start[1] + int(round(y / cell))
            image[row, col] = (40, 90, 255)
        col, row = self._episode.cell
        image[max(0, row - 1) : row + 2, max(0, col - 1) : col + 2] = (255, 40, 40)
        return image

    def close(self) -> None:
        self._lattices.kept.clear()
        super().close()


__all__ = ["ExploreEnv", "SLOT_OFFSETS", "STAY_SLOT"]
