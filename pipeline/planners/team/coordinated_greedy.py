"""Coordinated `greedy_utility`: Burgard et al.'s utility reduction around teammates' goals.

Every robot runs its own `greedy_utility` planner (its own lattice graph, updated from its own
observation) and chooses as greedy does, the reachable useful node with the most frontier
utility per metre of known path, except that each node's utility is first reduced near the
goals its teammates are heading for (Burgard, Moors, Stachniss, Schneider, "Coordinated
multi-robot exploration", IEEE T-RO 2005). A teammate's goal at distance d lowers a node's
utility by the share P(d) = 1 - d / range of what the teammate's scan there is likely to reveal
of it (0 beyond the range, the sensor range by default); several teammates' reductions
multiply, (1 - P(d1)) (1 - P(d2)) .... Burgard et al. subtract P(d) from a unit utility; scaled
by the node's own utility, one teammate's reduction is the same. A teammate's goal itself
(d = 0) is worth nothing, so it is chosen only when no other target is left.

Robots decide one at a time (`pipeline.world.team`): robots starting on one node decide in turn
at time 0, each seeing the goals of those before it, so they split up as in Burgard et al.'s
sequential assignment. Each robot replans at every node, as single-robot greedy does; what it
knows of its teammates' goals comes through `HeardGoals`.
"""

from __future__ import annotations

import dataclasses
from typing import Annotated, Any, cast

import numpy as np

from pipeline.common.config import config_dataclass, maybe, positive
from pipeline.planners.baselines.frontier import GreedyUtilityConfig, GreedyUtilityPlanner
from pipeline.planners.config import option
from pipeline.planners.registry import make_planner
from pipeline.planners.team.heard_goals import HeardGoals
from pipeline.planners.team.registry import register_team_planner
from pipeline.planners.wrapper import innermost
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Planner, Waypoint
from pipeline.world.protocol import Protocol
from pipeline.world.team import TeamObservation, TeamPlanner


@config_dataclass
class CoordinatedGreedyConfig(GreedyUtilityConfig):
    description = (
        "greedy utility per robot, utilities reduced near teammates' goals (Burgard et al. 2005) so that "
        "no two robots chase the same frontier"
    )

    reduction_range: Annotated[float | None, maybe(positive(), "the sensor range")] = option(
        None,
        "metres: a teammate's goal reduces the utility of nodes this near it, by 1 - distance / range "
        "[default: the protocol's sensor range]",
    )


def base_options(config: Any, base_config: type) -> dict[str, Any]:
    """The options of `config` that the single-robot planner's config `base_config` takes."""
    return {f.name: getattr(config, f.name) for f in dataclasses.fields(base_config)}


def reduction_factors(node_xy: np.ndarray, goals_xy: np.ndarray, reach: float) -> np.ndarray:
    """Burgard et al.'s remaining share of each node's utility after teammates' goals: the product
    over the goals of min(1, distance / reach) (0 at a goal, 1 at `reach` metres and beyond)."""
    factors = np.ones(len(node_xy))
    for goal in np.asarray(goals_xy, dtype=np.float64).reshape(-1, 2):
        distance = np.hypot(node_xy[:, 0] - goal[0], node_xy[:, 1] - goal[1])
        factors *= np.minimum(1.0, distance / reach)
    return factors


def burgard_choice(
    node_world: np.ndarray,
    utility: np.ndarray,
    targets: np.ndarray,
    dist: np.ndarray,
    teammates_goals: list[int],
    reach: float,
) -> int:
    """The target with the most utility per metre of path once utilities are reduced near
    `teammates_goals` (greedy's order on a tie: the first of `targets`); by plain utility per
    metre when every target is some teammate's goal. `utility` and `dist` are per lattice node."""
    value = utility[targets].astype(np.float64)
    if teammates_goals:
        reduced = value * reduction_factors(node_world[targets], node_world[np.asarray(teammates_goals)], reach)
        if reduced.max() > 0:
            value = reduced
    return int(targets[np.argmax(value / dist[targets])])


class CoordinatedGreedyTeam(TeamPlanner):
    """One `greedy_utility` planner per robot; each robot's targets scored by utility reduced near
    its teammates' goals, per metre of known path."""

    description = CoordinatedGreedyConfig.description

    def __init__(self, config: CoordinatedGreedyConfig = CoordinatedGreedyConfig()):
        self.config = config
        self.base = base_options(config, GreedyUtilityConfig)
        self.planners: list[Planner] = []
        self.last_decision: dict = {}

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int, robots: int) -> None:
        if len(self.planners) != robots:
            self.planners = [make_planner("greedy_utility", **self.base) for _ in range(robots)]
        for k, planner in enumerate(self.planners):
            planner.reset(frame, protocol, seed * 1009 + k)
        self.reach = float(
            protocol.sensor_range if self.config.reduction_range is None else self.config.reduction_range
        )
        self.goals = HeardGoals(robots)

    def plan(self, observation: TeamObservation) -> list[Waypoint]:
        planner = cast(GreedyUtilityPlanner, innermost(self.planners[observation.robot]))
        teammates = [g for g in self.goals.teammates_goals(observation) if g is not None]
        graph = planner.update_graph(observation.observation)
        robot = planner.robot_node(observation.observation)
        dist, pred = graph.shortest_paths(robot)
        targets = planner.reachable_useful(robot, dist)
        if targets.size == 0:
            self.goals.decided(observation, None)
            return []
        goal = burgard_choice(graph.node_world, graph.utility, targets, dist, teammates, self.reach)
        self.goals.decided(observation, goal)
        self.last_decision = {"robot": observation.robot, "goal": goal, "teammates_goals": teammates}
        return planner.waypoints_along(graph.path_from_predecessors(pred, goal))

    def check_protocol(self, protocol: Protocol) -> None:
        (self.planners[0] if self.planners else make_planner("greedy_utility", **self.base)).check_protocol(protocol)


@register_team_planner("greedy_utility", CoordinatedGreedyConfig)
def build_coordinated_greedy(config: CoordinatedGreedyConfig) -> TeamPlanner:
    return CoordinatedGreedyTeam(config)
