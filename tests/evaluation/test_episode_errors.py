"""A benchmark's planner that raises fails its episode (its trajectory so far kept); elsewhere it raises."""

from __future__ import annotations

import pytest

from pipeline.evaluation.episode_errors import ErrorsEndTheEpisode
from pipeline.world.planner import Planner
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode
from pipeline.world.team import TeamPlanner, run_team_episode


class BreaksOnItsSecondPlan(Planner):
    name = "breaks"

    def reset(self, frame, protocol, seed):
        self.calls = 0

    def plan(self, observation):
        self.calls += 1
        if self.calls == 2:
            raise RuntimeError("Padding size should be less than\n the input dimension")
        return [(4.0, 0.0)]


def test_the_episode_ends_with_the_error_and_the_trajectory_so_far(small_maze):
    planner = ErrorsEndTheEpisode(BreaksOnItsSecondPlan())
    result = run_episode(small_maze, planner, Protocol())
    assert result.trajectory == [(0.0, 0.0), (4.0, 0.0)] and not result.complete
    assert planner.error == "planner error: RuntimeError: Padding size should be less than the input dimension"
    assert "Traceback" in planner.error_traceback and "RuntimeError" in planner.error_traceback
    run_episode(small_maze, planner, Protocol())  # a new episode starts clean
    assert planner.error  # (it breaks again on its second plan)


def test_outside_a_benchmark_the_simulator_lets_a_planners_error_through(small_maze):
    with pytest.raises(RuntimeError, match="Padding size"):  # data collection and the teachers see it
        run_episode(small_maze, BreaksOnItsSecondPlan(), Protocol())


def test_a_team_planner_that_raises_ends_its_team_episode(small_maze):
    class Breaks(TeamPlanner):
        name = "breaks"

        def reset(self, frame, protocol, seed, robots):
            self.calls = 0

        def plan(self, observation):
            self.calls += 1
            if observation.robot == 1:
                raise ValueError("no node image for this lattice")
            return [(4.0, 0.0)] if self.calls == 1 else []

    planner = ErrorsEndTheEpisode(Breaks())
    team = run_team_episode(small_maze, planner, Protocol(), robots=2)
    assert not team.complete and planner.error == "planner error: ValueError: no node image for this lattice"
    assert len(team.rows) >= 2
