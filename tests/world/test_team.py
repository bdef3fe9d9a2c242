"""Team episodes: the event order, the motion rule per robot, shared and range-limited beliefs,
team files and their replay."""

from __future__ import annotations

import math

import numpy as np
import pytest

from pipeline.planners import make_planner
from pipeline.planners.team.registry import make_team_planner
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE
from pipeline.world.simulator import run_episode
from pipeline.world.team import TeamEpisode, TeamObservation, TeamPlanner, run_team_episode
from pipeline.world.team_files import merges_path, read_team_csv, write_merges_csv, write_team_csv
from pipeline.world.team_replay import replay_team


class Scripted(TeamPlanner):
    """Each robot follows its own list of plans, one per decision; [] once a list is used up."""

    name = "scripted"

    def __init__(self, plans: dict[int, list[list[tuple[float, float]]]]):
        self.plans = plans
        self.seen: list[TeamObservation] = []
        self.beliefs: list[np.ndarray] = []  # each decision's belief as it was then (the grid changes in place)

    def reset(self, frame, protocol, seed, robots):
        self.left = {robot: list(plans) for robot, plans in self.plans.items()}

    def plan(self, observation):
        self.seen.append(observation)
        self.beliefs.append(observation.observation.belief.copy())
        left = self.left.get(observation.robot, [])
        return left.pop(0) if left else []


def test_a_team_of_one_is_the_single_robot_episode(small_maze):
    single = run_episode(small_maze, make_planner("greedy_utility"), Protocol())
    team = run_team_episode(small_maze, make_team_planner("uncoordinated_greedy_utility"), Protocol(), robots=1)
    assert team.complete and single.complete
    assert [(x, y) for _, _, x, y in team.rows] == [tuple(p) for p in single.trajectory[: len(team.rows)]]
    assert team.makespan_m == pytest.approx(single.distance_m)
    assert team.total_distance_m == pytest.approx(single.distance_m)


def test_arrivals_come_in_time_order_each_at_its_robots_travelled_distance(small_maze):
    team = run_team_episode(
        small_maze,
        make_team_planner("uncoordinated_nearest_frontier"),
        Protocol(),
        robots=3,
        starts=[(0, 0), (0, 4), (4, 0)],
    )
    assert team.complete and not team.failure
    assert [row[:2] for row in team.rows[:3]] == [(0.0, 0), (0.0, 1), (0.0, 2)]  # the starts first
    times = [row[0] for row in team.rows]
    assert times == sorted(times)
    travelled = [0.0] * 3
    where = {k: team.rows[k][2:] for k in range(3)}
    for t, robot, x, y in team.rows[3:]:
        travelled[robot] += math.hypot(x - where[robot][0], y - where[robot][1])
        where[robot] = (x, y)
        assert t == pytest.approx(travelled[robot])  # one speed: a robot's clock is its travel
    assert team.robot_distance_m == pytest.approx(travelled)
    assert team.makespan_m == pytest.approx(times[-1])
    assert len(team.decision_ms) == 3 and all(team.decision_ms)


def test_a_move_through_cells_its_robot_does_not_know_is_refused(small_maze):
    planner = Scripted({0: [[(4.0, 0.0)]], 1: [[(0.0, 40.0)]]})  # 40 m straight down: walls and unknown cells
    team = run_team_episode(small_maze, planner, Protocol(), robots=2)
    assert not team.complete and team.motion_violations == 1
    assert "robot 1" in team.failure and "not known to be free" in team.failure


def test_every_robot_waiting_with_nothing_to_do_ends_the_episode(small_maze):
    team = run_team_episode(small_maze, Scripted({}), Protocol(), robots=2)
    assert not team.complete and team.failure == "no reachable target left for any robot"
    assert len(team.rows) == 2


def test_a_waiting_robot_asks_again_after_a_teammate_arrives(small_maze):
    class LateStarter(Scripted):
        def plan(self, observation):
            self.seen.append(observation)
            if observation.robot == 1 and observation.time_m == 0:
                return []  # nothing to do yet
            left = self.left.get(observation.robot, [])
            return left.pop(0) if left else []

    planner = LateStarter({0: [[(4.0, 0.0)]], 1: [[(0.0, 4.0)]]})
    team = run_team_episode(small_maze, planner, Protocol(), robots=2)
    asked = [(o.robot, o.time_m) for o in planner.seen]
    assert asked[:4] == [(0, 0.0), (1, 0.0), (0, 4.0), (1, 4.0)]  # asked again once robot 0 arrived
    assert any(robot == 1 and (x, y) == (0.0, 4.0) for _, robot, x, y in team.rows)


def test_teammates_see_each_others_positions_and_targets(small_maze):
    planner = Scripted({0: [[(4.0, 0.0)]], 1: [[(0.0, 4.0)]]})
    run_team_episode(small_maze, planner, Protocol(), robots=2)
    second = planner.seen[1]  # robot 1 at time 0, after robot 0 chose
    assert second.robot == 1 and second.targets[0] == (4.0, 0.0) and second.positions == ((0.0, 0.0), (0.0, 0.0))
    assert second.connected == (True, True)


def test_a_shared_belief_hands_each_robot_the_cells_its_teammates_revealed(small_maze):
    planner = Scripted({0: [[(4.0, 0.0)], [(8.0, 0.0)]], 1: [[(0.0, 4.0)], [(0.0, 8.0)]]})
    run_team_episode(small_maze, planner, Protocol(), robots=2)
    later = [o for o in planner.seen if o.robot == 1 and o.time_m > 0][0]
    assert later.observation.changed is not None and later.observation.changed.size > 0
    assert planner.seen[0].observation.belief is later.observation.belief  # one belief for the team


def test_out_of_range_robots_keep_their_own_beliefs_and_merge_when_they_meet(small_maze):
    down = [(0.0, 4.0 * k) for k in (1, 2, 3, 4, 3, 2, 1, 0)]  # down the left corridor and back
    right = [(4.0 * k, 0.0) for k in (1, 2, 3, 2, 1, 0)]  # along the top corridor and back
    planner = Scripted({0: [[p] for p in down], 1: [[p] for p in right]})
    team = run_team_episode(small_maze, planner, Protocol(), robots=2, comm_range_m=6.0)
    at = {(o.robot, o.time_m): k for k, o in enumerate(planner.seen)}
    apart = planner.seen[at[1, 12.0]]
    assert apart.connected == (False, True)
    assert apart.positions[0] == pytest.approx((0.0, 4.0))  # where robot 0 was when they last heard each other
    assert not np.array_equal(planner.beliefs[at[0, 12.0]], planner.beliefs[at[1, 12.0]])
    back = [o for o in planner.seen if o.robot == 1 and o.time_m == 32.0][0]
    assert back.connected == (True, True)
    assert team.merges and all(group == (0, 1) for _, group in team.merges)
    assert team.merges[-1][0] > 12.0  # they merged again on meeting
    assert team.comm_range_m == 6.0


def test_the_done_rule_counts_the_union_of_beliefs(small_maze):
    protocol = Protocol()
    full = run_team_episode(
        small_maze, make_team_planner("uncoordinated_nearest_frontier"), protocol, robots=2, starts=[(0, 0), (4, 0)]
    )
    ranged = run_team_episode(
        small_maze,
        make_team_planner("uncoordinated_nearest_frontier"),
        protocol,
        robots=2,
        starts=[(0, 0), (4, 0)],
        comm_range_m=1.0,
    )
    assert full.complete and ranged.complete
    assert ranged.explored_ratio >= 1 - protocol.done_unknown_cells / small_maze.free_cell_count


def test_team_files_round_trip_and_replay_clean(small_maze, tmp_path):
    team = run_team_episode(
        small_maze,
        make_team_planner("uncoordinated_greedy_utility"),
        Protocol(),
        robots=2,
        starts=[(0, 0), (0, 4)],
        comm_range_m=10.0,
    )
    path = write_team_csv(tmp_path / "small.team.csv", team.rows, speed_mps=2.0)
    assert path.read_text().splitlines()[0] == "time_s,robot,x,y"
    rows = read_team_csv(path)
    assert [(r, x, y) for _, r, x, y in rows] == [(r, x, y) for _, r, x, y in team.rows]
    assert rows[-1][0] == pytest.approx(team.makespan_m / 2.0, abs=1e-5)
    replayed = replay_team(small_maze, rows, Protocol())
    assert replayed.complete and not replayed.failure and replayed.robots == 2
    assert replayed.robot_distance_m == pytest.approx(team.robot_distance_m, abs=1e-4)
    merges = write_merges_csv(merges_path(path), team.merges, speed_mps=2.0)
    assert merges.name == "small.team.merges.csv" and merges.read_text().startswith("time_s,robots\n")


def test_a_replay_refuses_a_segment_the_team_had_not_seen(small_maze, tmp_path):
    path = tmp_path / "bad.team.csv"
    path.write_text("time_s,robot,x,y\n0,0,0,0\n0,1,0,0\n20,1,0,40\n")
    replayed = replay_team(small_maze, read_team_csv(path), Protocol())
    assert not replayed.complete and replayed.motion_violations == 1 and "robot 1" in replayed.failure


@pytest.mark.parametrize(
    "text, message",
    [
        ("x,y\n0,0\n", "starts with the header"),
        ("time_s,robot,x,y\n0,0,0,0\n5,0,4,0\n3,0,8,0\n", "goes back"),
        ("time_s,robot,x,y\n0,0,0,0\n4,1,4,0\n", "robot 1 has no start row"),
        ("time_s,robot,x,y\n0,0,0,0\n4,9,4,0\n", "robot must be a whole number 0-7"),
        ("time_s,robot,x,y\n0,0,0,0\n4,0,nan,0\n", "finite"),
        ("time_s,robot,x,y\n", "no rows"),
    ],
)
def test_bad_team_files_are_refused_with_the_line(tmp_path, text, message):
    path = tmp_path / "t.team.csv"
    path.write_text(text)
    with pytest.raises(ValueError, match=message):
        read_team_csv(path)


def test_bad_team_settings_are_refused(small_maze):
    with pytest.raises(ValueError, match="robots must be 1-8"):
        TeamEpisode(small_maze, Protocol(), 9)
    with pytest.raises(ValueError, match="2 starts given for 3 robots"):
        TeamEpisode(small_maze, Protocol(), 3, starts=[(0, 0), (0, 4)])
    with pytest.raises(ValueError, match="comm_range_m must be a positive"):
        TeamEpisode(small_maze, Protocol(), 2, comm_range_m=0.0)
    with pytest.raises(ValueError, match="not a free cell"):
        TeamEpisode(small_maze, Protocol(), 2, starts=[(0, 0), (-8, 0)])


def test_a_start_shares_its_first_scan_with_the_whole_team(small_maze):
    episode = TeamEpisode(small_maze, Protocol(), 2, starts=[(0, 0), (0, 4)])
    seen = episode.observe(0).observation.belief
    assert (seen == FREE).sum() == episode.union.free_count > 0
    assert np.array_equal(seen, episode.observe(1).observation.belief)
