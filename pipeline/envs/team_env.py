"""`guide_team_explore_v0`: a PettingZoo ParallelEnv over team episodes (docs/teams.md).

The environment drives a `TeamEpisode` (pipeline/world/team.py) through the same event loop as
`run_team_episode`: events in time order, the robot that arrives next senses, the beliefs update
(and merge within `comm_range_m`), and a robot whose plan is used up decides. The episode is the
referee of sensing, the motion rule and the done rule; this module only stands where the team
planner stands in `run_team_episode`.

Who acts: decisions in a team episode are taken one at a time, each seeing the beliefs and the
teammates' targets left by the decisions before it (robots that arrive at the same moment decide
in turn, lower numbers first). So at every step exactly one agent acts: the robot whose decision
comes next in that order. Its action mask shows its moves and `stay` (wait for the next arrival);
every other agent's mask shows `stay` only and its action is ignored. After the acting robot's
decision the environment runs the team's clock on to the next decision. An agent's observation
and info say whether it acts (`acting`).

Each robot observes what `guide/Explore-v0`'s robot observes, on its own belief (the team's with
full communication): the observed graph arrays (`pipeline.prediction.observed_graph`) and the action
mask; plus its teammates' positions and targets as it last heard them, relative to it. Each robot
keeps its own lattice graph (one for the team with full communication), updated with the cells
its belief changed, so `env.episode.observe(k)` stays a planner's own, as under `run_team_episode`.

Rewards are `guide/Explore-v0`'s terms per robot: free area its own scans added to the team's
knowledge, minus the distance of the moves it finished, the completion bonus to every robot, and
the penalty for a masked action to the robot that chose it (which then waits).
"""

from __future__ import annotations

import copy
import warnings
from typing import Any, cast

import numpy as np
from gymnasium import spaces
from gymnasium.utils import seeding
from pettingzoo import ParallelEnv

from pipeline.envs.configuration_team import TeamExploreEnvConfig
from pipeline.envs.explore_env import (
    ExploreEnv,
    LatticeCache,
    checked_action,
    graph_observation,
    reward_info,
    waypoint_action,
)
from pipeline.envs.map_sources import DrawnMap
from pipeline.lattice.graph import LatticeGraph
from pipeline.prediction.observed_graph import STAY_SLOT, ObservedStep, observe_lattice, window_moves
from pipeline.world.episode import IDLE, MOTION_RULE, MOVE_LIMIT, EventLoop
from pipeline.world.map_files import MapError
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol, protocol_for_map
from pipeline.world.team import MAX_ROBOTS, TeamEpisode, TeamEpisodeResult

#: Per teammate row of the `teammates` observation (robot-number order, this robot left out, zero padded).
TEAMMATE_COLUMNS = ("present", "connected", "dx", "dy", "has_target", "target_dx", "target_dy")
ENV_NAME = "guide_team_explore_v0"
OPTION_KEYS = ("map", "starts")


class TeamExploreEnv(ParallelEnv):
    """A team of robots exploring one map, one agent per robot; see the module's doc and docs/teams.md.

    `TeamExploreEnv(robots=3, map="maze", comm_range_m=None, ...)` takes `TeamExploreEnvConfig`'s
    fields as keywords (or `config=`), and `protocol=` a `Protocol` (or its dict) for the protocol
    fields at once. `reset(options={"map": ground_truth, "starts": [...]})` runs one episode on a
    given map (and starts) instead of the configured source's.
    """

    metadata = {"name": ENV_NAME, "render_modes": [], "is_parallelizable": True}

    def __init__(
        self, config: TeamExploreEnvConfig | None = None, protocol: Protocol | dict | None = None, **values: Any
    ):
        if config is not None and (values or protocol is not None):
            raise ValueError("pass either config= or keyword parameters, not both")
        self.config = config if config is not None else TeamExploreEnvConfig.from_kwargs(protocol, **values)
        # The single-robot environment of the same settings: its map source, graph settings and spaces
        # are each robot's (it is never reset or stepped).
        self.single = ExploreEnv(config=self.config.explore_config())
        self.source = self.single.source
        self.graph_config = self.single.graph_config
        self.action_count = self.single.action_count
        self.possible_agents = [f"robot_{k}" for k in range(self.config.robots)]
        self.agents: list[str] = []
        base = self._observation_space()
        self._observation_spaces = {agent: copy.deepcopy(base) for agent in self.possible_agents}
        self._action_spaces = {agent: spaces.Discrete(self.action_count) for agent in self.possible_agents}
        self._lattice_cache = LatticeCache(size=1)  # the last map file's
        self._episode: TeamEpisode | None = None
        self._acting: int | None = None  # the robot whose action the next step uses
        self._failure = ""
        self.np_random, self.np_random_seed = seeding.np_random(None)

    # ------------------------------------------------------------------ spaces
    def _observation_space(self) -> spaces.Dict:
        """`guide/Explore-v0`'s observation space plus the teammates' rows and whether the robot acts."""
        keys = dict(cast(spaces.Dict, self.single.observation_space).spaces)
        rows, columns = MAX_ROBOTS - 1, len(TEAMMATE_COLUMNS)
        keys["teammates"] = spaces.Box(-np.inf, np.inf, (rows, columns), dtype=np.float32)
        keys["acting"] = spaces.Discrete(2)
        return spaces.Dict(keys)

    def observation_space(self, agent: str) -> spaces.Dict:
        return self._observation_spaces[agent]

    def action_space(self, agent: str) -> spaces.Discrete:
        return self._action_spaces[agent]

    # ------------------------------------------------------------------ read-only views
    @property
    def episode(self) -> TeamEpisode:
        """The team episode (read-only: never move it). `episode.observe(k)` is robot k's planner's
        own: the environment never calls it, so a planner sees every change since its last call."""
        self._require_episode()
        return cast(TeamEpisode, self._episode)

    @property
    def ground_truth(self) -> GroundTruthMap:
        """The map of the current episode."""
        return self.episode.map

    @property
    def protocol(self) -> Protocol:
        """The protocol of the current episode (a ROS map brings its own cell size)."""
        self._require_episode()
        return self._protocol

    @property
    def acting_agents(self) -> list[str]:
        """The agents whose actions the next `step` uses: the one robot that decides next, or none."""
        return [] if self._acting is None else [self.possible_agents[self._acting]]

    @property
    def failure(self) -> str:
        """Why an episode ended with the map unexplored, in `run_team_episode`'s words (or the
        environment's step limit); "" while it runs and when it is complete."""
        return self._failure

    def lattice(self, agent: str) -> LatticeGraph:
        """The lattice graph of the agent's belief, up to date with it (read-only)."""
        return self._lattices[self._index(agent)]

    def visited(self, agent: str) -> np.ndarray:
        """Per lattice node, whether the agent knows a robot of the team has stood on it (read-only): the
        `visited` feature. Robots that talk share it, as they share their beliefs."""
        return self._visited[self._index(agent)]

    def row_nodes(self, agent: str) -> np.ndarray:
        """The lattice node id of each filled row of the agent's last observation, nearest it first."""
        return self._views[self._index(agent)].row_nodes

    def action_masks(self, agent: str) -> np.ndarray:
        """Which of the agent's actions are valid now (only `stay` for an agent that does not act)."""
        self._require_episode()
        return self._masks[self._index(agent)].astype(bool)

    def stay_action(self, agent: str) -> int:
        """The action that makes the agent wait for the next arrival (the only valid one while it does not act)."""
        return STAY_SLOT if self.config.action == "neighbour" else self._views[self._index(agent)].robot_row

    def action_for_waypoint(self, agent: str, waypoint) -> int:
        """The action that moves the agent's robot to a lattice waypoint (metres): its slot in neighbour
        mode (the waypoint must lie in the robot's 5 x 5 window), its row in node mode. ValueError when
        the waypoint has no action (out of the window, not among the rows)."""
        k = self._index(agent)
        position = self.episode.robots[k].position
        return waypoint_action(self.config.action, self._lattices[k], self._views[k], position, waypoint, agent)

    def team_result(self, planner: str = ENV_NAME) -> TeamEpisodeResult:
        """The episode's figures as `run_team_episode` reports them (no decision times: the agents decide)."""
        episode = self.episode
        return episode.result(planner, [[] for _ in episode.robots], self._failure, self._violations, self._seed)

    def _index(self, agent: str) -> int:
        if agent not in self.possible_agents:
            raise KeyError(f"unknown agent {agent!r}; the agents are {', '.join(self.possible_agents)}")
        self._require_episode()
        return self.possible_agents.index(agent)

    def _require_episode(self) -> None:
        if self._episode is None:
            raise RuntimeError("reset() the environment first")

    # ------------------------------------------------------------------ episode
    def reset(self, seed: int | None = None, options: dict[str, Any] | None = None):
        """A new episode: the source's next map (a fresh maze for map="maze") or `options["map"]`, a
        `GroundTruthMap`; the robots at the configured starts or `options["starts"]` (metres from
        the map's start)."""
        if seed is not None:
            self.np_random, self.np_random_seed = seeding.np_random(seed)
        options = dict(options or {})
        unknown = sorted(set(options) - set(OPTION_KEYS))
        if unknown:
            warnings.warn(
                f"reset options {', '.join(unknown)} are not used; the options are {', '.join(OPTION_KEYS)}",
                stacklevel=2,
            )
        drawn = self._draw(options.get("map"))
        starts = options.get("starts", self.config.starts)
        cfg = self.config
        self._drawn, self._protocol = drawn, drawn.protocol
        self._seed = int(seed) if seed is not None else 0
        self._episode = TeamEpisode(drawn.ground_truth, drawn.protocol, cfg.robots, starts, cfg.comm_range_m)
        episode = self._episode
        # Robots that hold one belief share one lattice graph and one record of the nodes stood on.
        lattice, self._table = self._lattice_cache.fresh(drawn)
        beliefs = list({id(belief): belief for belief in episode.beliefs}.values())
        graphs = [lattice] + [copy.deepcopy(lattice) for _ in beliefs[1:]]  # copied while still empty
        holders: dict[int, tuple[LatticeGraph, np.ndarray, np.ndarray]] = {}
        for belief, graph in zip(beliefs, graphs):
            graph.update(belief.grid, None)
            holders[id(belief)] = (graph, belief.grid.copy(), np.zeros(graph.node_count, dtype=bool))
        self._lattices = [holders[id(b)][0] for b in episode.beliefs]
        self._seen = [holders[id(b)][1] for b in episode.beliefs]  # the belief each lattice graph reflects
        self._visited = [holders[id(b)][2] for b in episode.beliefs]
        self._holders = [[k for k, b in enumerate(episode.beliefs) if id(b) == key] for key in holders]
        for k in range(cfg.robots):
            self._stand(k)
        self._share_visits()
        self._loop = EventLoop(episode)  # run_team_episode's: every robot decides at time 0, in number order
        self._known = episode.union.free_count  # the team's known free cells after the last event
        self._steps, self._acting = 0, None
        self._ended, self._failure = False, ""  # whether no event is left to run, and why (unless complete)
        self._move_limit, self._violations = False, 0  # ended on the robots' move limit; motion rule broken
        self._scanned = [0] * cfg.robots  # cells each robot's scans added to the team's belief this step
        self.agents = list(self.possible_agents)
        self._advance()
        self._refresh()
        zero: dict[str, Any] = {"invalid": False, "area": 0.0, "distance": 0.0, "parts": (0.0, 0.0, 0.0, 0.0)}
        return self._observations(), {agent: self._info(k, **zero) for k, agent in enumerate(self.agents)}

    def _draw(self, given: GroundTruthMap | None) -> DrawnMap:
        """The episode's map: the given one under the configured protocol, or the source's next."""
        if given is None:
            return self.source.draw(self.np_random)
        if not isinstance(given, GroundTruthMap):
            raise ValueError(f"options['map'] must be a GroundTruthMap, got {type(given).__name__}")
        try:
            return DrawnMap(given, protocol_for_map(self.config.protocol(), given), "")
        except MapError as error:
            raise ValueError(f"options['map']: {error}") from None

    def step(self, actions: dict[str, Any]):
        if self._episode is None or not self.agents:
            raise RuntimeError("the episode is over (or never began): call reset()")
        episode, cfg = self._episode, self.config
        acting = self._acting
        if acting is not None:
            agent = self.possible_agents[acting]
            if agent not in actions:
                raise ValueError(f"{agent} acts at this step: actions must hold its action")
            action = checked_action(actions[agent], self.action_count)
        self._steps += 1
        was_complete = episode.complete
        travelled_before = [r.travelled for r in episode.robots]
        self._scanned = [0] * cfg.robots
        invalid = [False] * cfg.robots
        if acting is not None:
            invalid[acting] = not self._masks[acting][action]
            stay = invalid[acting] or action == self.stay_action(agent)
            self._loop.decide(acting, [] if stay else self._waypoints(acting, action))
            self._advance()
        terminated = self._ended and not self._move_limit  # a move limit truncates; any other end is terminal
        truncated = not terminated and (self._ended or self._steps >= cfg.steps_allowed)
        if truncated and not self._ended:
            self._failure = f"environment step limit ({cfg.steps_allowed} steps) reached"
        if terminated or truncated:
            self._ended, self._acting = True, None  # nobody acts any more
        self._refresh()
        cell_area = self._protocol.cell_size**2
        bonus = cfg.completion_bonus if episode.complete and not was_complete else 0.0
        observations, rewards, infos = self._observations(), {}, {}
        for k, agent in enumerate(self.agents):
            area = self._scanned[k] * cell_area
            distance = episode.robots[k].travelled - travelled_before[k]
            parts = (
                cfg.area_weight * area,
                -cfg.distance_weight * distance,
                bonus,
                -cfg.invalid_action_penalty if invalid[k] else 0.0,
            )
            rewards[agent] = float(sum(parts))
            infos[agent] = self._info(k, invalid=invalid[k], area=area, distance=distance, parts=parts)
        terminations = {agent: bool(terminated) for agent in self.agents}
        truncations = {agent: bool(truncated) for agent in self.agents}
        if terminated or truncated:
            self.agents = []
        return observations, rewards, terminations, truncations, infos

    def _waypoints(self, k: int, action: int) -> list[tuple[float, float]]:
        """The lattice waypoints (metres) a valid move action sends robot k through: the neighbour in the
        action's slot, or the shortest known path to the action's row (its own node left out)."""
        view, lattice = self._views[k], self._lattices[k]
        if self.config.action == "neighbour":
            nodes = [int(self._table.neighbour[view.robot_node, action])]
        else:
            nodes = lattice.path_from_predecessors(view.predecessors, int(view.row_nodes[action]))[1:]
        return cast(list[tuple[float, float]], [tuple(map(float, lattice.node_world[node])) for node in nodes])

    # ------------------------------------------------------------------ the event loop (run_team_episode's)
    def _advance(self) -> None:
        """Run the team's events until a robot must decide (it becomes the acting one) or the
        episode ends: `run_team_episode`'s loop, with this environment's agents as the planner."""
        self._acting = self._loop.next_decision(self._on_event)
        if self._acting is not None:
            return
        self._ended, ending = True, self._loop.ending
        self._move_limit = ending == MOVE_LIMIT
        if ending and not self._failure:
            self._violations = int(ending.startswith(MOTION_RULE))
            self._failure = {
                MOVE_LIMIT: f"step limit ({self._protocol.max_steps} moves of a robot) reached",
                IDLE: "no reachable target left for any robot",
            }.get(ending, ending)

    def _on_event(self, index: int) -> None:
        """After robot `index`'s event: what its scan added to the team's belief, the node it stands
        on, and the visits shared within each linked group."""
        known = self.episode.union.free_count
        self._scanned[index] += known - self._known
        self._known = known
        self._stand(index)
        self._share_visits()

    def _stand(self, index: int) -> None:
        """Mark robot `index`'s node as stood on (the `visited` feature)."""
        position = self.episode.robots[index].position
        self._visited[index][self._lattices[index].nearest_node(position)] = True

    def _share_visits(self) -> None:
        """Robots that talk share which nodes the team has stood on, as they share their beliefs."""
        if len(self._holders) == 1:
            return
        for group in self.episode.groups():
            if len(group) > 1:
                merged = np.logical_or.reduce([self._visited[k] for k in group])
                for k in group:
                    self._visited[k][...] = merged

    # ------------------------------------------------------------------ observations
    def _refresh(self) -> None:
        """Bring every lattice graph up to date with its belief, then rebuild each robot's view and mask."""
        episode = cast(TeamEpisode, self._episode)
        for group in self._holders:
            grid, seen = episode.beliefs[group[0]].grid, self._seen[group[0]]
            changed = np.flatnonzero(grid != seen)
            if changed.size:
                seen.flat[changed] = grid.flat[changed]
                self._lattices[group[0]].update(grid, changed)
        self._views: list[ObservedStep] = []
        self._masks: list[np.ndarray] = []
        for k, robot in enumerate(episode.robots):
            view = observe_lattice(
                self._lattices[k],
                self._table,
                robot.position,
                self._visited[k],
                self.graph_config,
                self.config.max_neighbors,
            )
            mask = np.zeros(self.action_count, dtype=np.int8)
            if k == self._acting:
                if self.config.action == "neighbour":
                    mask[:] = window_moves(self._lattices[k], self._table, view.robot_node)
                else:
                    filled = len(view.row_nodes)
                    mask[:filled] = np.isfinite(view.distance[view.row_nodes])
            stay = STAY_SLOT if self.config.action == "neighbour" else view.robot_row
            mask[stay] = 1  # waiting is always allowed; it is all a robot that does not act can do
            self._views.append(view)
            self._masks.append(mask)

    def _observations(self) -> dict[str, dict[str, Any]]:
        return {agent: self._observation(k) for k, agent in enumerate(self.agents)}

    def _observation(self, k: int) -> dict[str, Any]:
        return {
            **graph_observation(self._views[k], self._masks[k]),
            "teammates": self._teammates(k),
            "acting": np.int64(k == self._acting),
        }

    def _teammates(self, k: int) -> np.ndarray:
        """Robot k's teammates as it last heard of them (the `TeamObservation` it would get), relative
        to it and scaled as the node features are; read from the episode without `observe`, which
        would hand a planner's pending changes to the environment."""
        episode = cast(TeamEpisode, self._episode)
        scale = self.graph_config.position_scale_nodes * self._protocol.node_resolution
        x, y = episode.robots[k].position
        rows = np.zeros((MAX_ROBOTS - 1, len(TEAMMATE_COLUMNS)), dtype=np.float32)
        others = [j for j in range(len(episode.robots)) if j != k]
        for row, j in enumerate(others):
            px, py = episode.heard_positions[k][j]
            target = episode.heard_targets[k][j]
            rows[row, :4] = (1.0, float(episode.connected[k][j]), (px - x) / scale, (py - y) / scale)
            if target is not None:
                rows[row, 4:] = (1.0, (target[0] - x) / scale, (target[1] - y) / scale)
        return rows

    def _info(
        self, k: int, invalid: bool, area: float, distance: float, parts: tuple[float, float, float, float]
    ) -> dict[str, Any]:
        episode = cast(TeamEpisode, self._episode)
        robot = episode.robots[k]
        return {
            "action_mask": self._masks[k].copy(),
            "acting": k == self._acting,
            "map_name": episode.map.name,
            "steps": self._steps,
            "time_m": episode.time,
            "moves": robot.moves,
            "distance": robot.travelled,
            "explored_share": episode.union.free_count / max(1, episode.map.free_cell_count),
            "complete": episode.complete,
            "failure": self._failure,
            "invalid_action": invalid,
            **reward_info(area, distance, parts),
        }

    def close(self) -> None:
        self._lattice_cache.kept.clear()
        self.single.close()


__all__ = ["ENV_NAME", "TEAMMATE_COLUMNS", "TeamExploreEnv"]
