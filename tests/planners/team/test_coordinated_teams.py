"""Coordinated team planners (pipeline/planners/team/coordinated_greedy.py, coordinated_tour.py) on 50 m mazes."""

from __future__ import annotations

import numpy as np
import pytest

from pipeline.planners.team.coordinated_greedy import CoordinatedGreedyTeam, reduction_factors
from pipeline.planners.team.coordinated_tour import CoordinatedTourTeam, CoordinatedTourVoteTeam
from pipeline.planners.team.heard_goals import HeardGoals
from pipeline.planners.team.registry import is_coordinated, make_team_planner
from pipeline.world.maps import list_maps, load_map
from pipeline.world.planner import Observation
from pipeline.world.protocol import Protocol
from pipeline.world.team import TeamObservation, TeamPlanner, run_team_episode
from pipeline.world.team_files import read_team_csv, write_team_csv
from pipeline.world.team_replay import replay_team

PROTOCOL = Protocol()
FAST_GUIDE = {"num_inference_steps": 2}  # the shipped policy with few denoising steps: a quick test, same machinery


@pytest.fixture(scope="module")
def mazes(generated_maze_dir):
    return [load_map(path) for path in list_maps(generated_maze_dir)]


class FirstGoals(TeamPlanner):
    """A coordinated team planner that records each robot's goal after its first decision."""

    def __init__(self, inner: TeamPlanner):
        self.inner, self.name = inner, inner.name
        self.first: dict[int, int | None] = {}

    def reset(self, frame, protocol, seed, robots):
        self.inner.reset(frame, protocol, seed, robots)

    def plan(self, observation):
        waypoints = self.inner.plan(observation)
        self.first.setdefault(observation.robot, self.inner.goals.goals[observation.robot])
        return waypoints


def test_the_coordinated_names_are_registered_with_their_options():
    assert all(is_coordinated(name) for name in ("greedy_utility", "guide_tsp", "guide"))
    assert isinstance(make_team_planner("greedy_utility", reduction_range=12.0), CoordinatedGreedyTeam)
    assert isinstance(make_team_planner("guide_tsp", routes_exact_max=6, routes_time_ms=10), CoordinatedTourTeam)
    assert isinstance(make_team_planner("guide", **FAST_GUIDE), CoordinatedTourVoteTeam)
    with pytest.raises(ValueError, match="reduction_range"):
        make_team_planner("greedy_utility", reduction_range=-1.0)
    with pytest.raises(ValueError, match="mode"):
        make_team_planner("guide", mode="policy")
    with pytest.raises(ValueError, match="lookahead"):
        make_team_planner("guide", lookahead=2)


def test_the_utility_reduction_falls_with_distance_over_the_range():
    nodes = np.array([[0.0, 0.0], [5.0, 0.0], [20.0, 0.0], [40.0, 0.0]])
    assert reduction_factors(nodes, np.array([[0.0, 0.0]]), 20.0) == pytest.approx([0.0, 0.25, 1.0, 1.0])
    both = reduction_factors(nodes, np.array([[0.0, 0.0], [40.0, 0.0]]), 20.0)  # reductions multiply
    assert both == pytest.approx([0.0, 0.25, 1.0, 0.0])


@pytest.mark.parametrize(
    "name,options,robots", [("greedy_utility", {}, 3), ("guide_tsp", {}, 3), ("guide", FAST_GUIDE, 2)]
)
def test_coordinated_teams_complete_and_their_files_replay_clean(mazes, tmp_path, name, options, robots):
    for maze in mazes if name != "guide" else mazes[:1]:
        result = run_team_episode(maze, make_team_planner(name, **options), PROTOCOL, robots)
        assert result.complete, result.failure
        assert result.motion_violations == 0
        path = write_team_csv(tmp_path / f"{maze.name}.team.csv", result.rows)
        replay = replay_team(maze, read_team_csv(path), PROTOCOL)
        assert replay.complete and replay.motion_violations == 0, replay.failure
        assert replay.makespan_s == pytest.approx(result.makespan_m, abs=1e-3)


@pytest.mark.parametrize("name,options", [("greedy_utility", {}), ("guide_tsp", {}), ("guide", FAST_GUIDE)])
def test_robots_from_one_start_head_for_different_targets(mazes, name, options):
    for maze in mazes if name != "guide" else mazes[:1]:
        planner = FirstGoals(make_team_planner(name, **options))
        run_team_episode(maze, planner, PROTOCOL, robots=2)
        assert planner.first[0] is not None and planner.first[0] != planner.first[1], maze.name


def test_coordinated_greedy_finishes_sooner_than_uncoordinated_greedy(mazes):
    coordinated = [run_team_episode(m, make_team_planner("greedy_utility"), PROTOCOL, 3).makespan_m for m in mazes]
    blind = [
        run_team_episode(m, make_team_planner("uncoordinated_greedy_utility"), PROTOCOL, 3).makespan_m for m in mazes
    ]
    assert sum(coordinated) < sum(blind)
    assert sum(c < b for c, b in zip(coordinated, blind)) >= 2, (coordinated, blind)


def test_a_coordinated_team_completes_under_a_communication_range(mazes):
    for name in ("greedy_utility", "guide_tsp"):
        result = run_team_episode(
            mazes[1], make_team_planner(name), PROTOCOL, 3, starts=[(0, 0), (0, 0), (0, 0)], comm_range_m=12.0
        )
        assert result.complete, (name, result.failure)


def observation(robot: int, connected: tuple[bool, ...]) -> TeamObservation:
    own = Observation(np.zeros((1, 1), dtype=np.uint8), (0.0, 0.0), (0, 0), None, 0)
    return TeamObservation(robot, own, ((0.0, 0.0),) * len(connected), (None,) * len(connected), connected, 0.0)


def test_goals_pass_only_on_the_links_the_episode_reports():
    goals = HeardGoals(3)
    goals.decided(observation(0, (True, False, True)), 11)  # robot 0 linked to robot 2 only
    assert goals.teammates_goals(observation(1, (False, True, False))) == [None, None, None]
    goals.decided(observation(1, (False, True, False)), 12)
    assert goals.teammates_goals(observation(2, (False, False, True))) == [11, None, None]  # heard from robot 0 before
    assert goals.teammates_goals(observation(2, (True, True, True))) == [11, 12, None]
    goals.decided(observation(0, (True, False, False)), 13)  # out of contact: robot 2 still knows 11
    assert goals.teammates_goals(observation(2, (False, False, True))) == [11, 12, None]
