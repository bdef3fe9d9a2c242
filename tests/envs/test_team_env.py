"""guide_team_explore_v0: PettingZoo's API test, who acts when, team episodes as `run_team_episode`
runs them, rewards, communication range and the single-robot environment's observation."""

from __future__ import annotations

import contextlib
import io
import re
import warnings

import numpy as np
import pytest
from import_graph import ROOT
from pettingzoo.test import parallel_api_test

from pipeline.envs import ExploreEnv
from pipeline.envs.team_env import TEAMMATE_COLUMNS, TeamExploreEnv
from pipeline.lattice.graph import LatticeGraph
from pipeline.lattice.spec import LatticeSpec
from pipeline.planners import make_planner
from pipeline.planners.team.registry import make_team_planner
from pipeline.prediction.observed_graph import SLOT_OFFSETS, STAY_SLOT
from pipeline.world.geometry import segment_is_known_free
from pipeline.world.protocol import Protocol
from pipeline.world.sensor import FREE
from pipeline.world.simulator import MotionError
from pipeline.world.team import MAX_ROBOTS, lattice_cell, reset_team_planner, run_team_episode

STARTS = [(0.0, 0.0), (0.0, 4.0), (4.0, 0.0)]  # free lattice nodes of the small maze


def api_test(env: TeamExploreEnv, cycles: int) -> None:
    """PettingZoo's parallel API test with every warning an error (its own complaints are warnings),
    but the one this environment gives for the unknown reset option the test passes on purpose."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        warnings.filterwarnings("ignore", message="reset options options are not used")
        parallel_api_test(env, num_cycles=cycles)


def masked_random_actions(env: TeamExploreEnv, obs: dict, rng: np.random.Generator) -> dict[str, int]:
    return {agent: int(rng.choice(np.flatnonzero(obs[agent]["action_mask"]))) for agent in env.agents}


def drive(env: TeamExploreEnv, obs: dict, planner_name: str, seed: int = 0, check=None):
    """Step the environment, from its observations `obs`, with what a team planner decides: when a robot
    acts with its plan used up the planner is asked (on `env.episode.observe`, as `run_team_episode`
    asks it), and each waypoint of the plan is one neighbour action. At every question the acting
    robot's `teammates` rows must be what its `TeamObservation` says; `check(env)` runs before every step."""
    planner = make_team_planner(planner_name)
    reset_team_planner(planner, env.ground_truth, env.protocol, seed, len(env.possible_agents))
    scale = env.graph_config.position_scale_nodes * env.protocol.node_resolution
    plans: dict[int, list] = {}
    while env.agents:
        if check is not None:
            check(env)
        actions = {agent: env.stay_action(agent) for agent in env.agents}
        for agent in env.acting_agents:
            k = env.possible_agents.index(agent)
            if not plans.get(k):
                observation = env.episode.observe(k)
                plans[k] = list(planner.plan(observation))
                x, y = observation.observation.position
                for row, j in enumerate(j for j in range(observation.robots) if j != k):
                    (px, py), target = observation.positions[j], observation.targets[j]
                    expected = [1.0, observation.connected[j], (px - x) / scale, (py - y) / scale, 0.0, 0.0, 0.0]
                    if target is not None:
                        expected[4:] = [1.0, (target[0] - x) / scale, (target[1] - y) / scale]
                    np.testing.assert_allclose(obs[agent]["teammates"][row], expected, rtol=1e-6, atol=1e-7)
            if plans[k]:
                actions[agent] = env.action_for_waypoint(agent, plans[k].pop(0))
        obs, _, _, _, infos = env.step(actions)
        assert not any(info["invalid_action"] for info in infos.values())
    return env.team_result(planner_name)


# ---------------------------------------------------------------------------------- PettingZoo
@pytest.mark.parametrize("robots, options", [(2, {}), (3, {}), (3, {"comm_range_m": 10.0}), (2, {"action": "node"})])
def test_pettingzoos_parallel_api_test_passes(robots, options):
    env = TeamExploreEnv(robots=robots, maze_side_m=50.0, **options)
    api_test(env, cycles=3000)
    assert env.agents == []  # the test ran episodes to their end, not just 3000 steps of one


def test_agents_and_spaces():
    env = TeamExploreEnv(robots=3, maze_side_m=50.0)
    single = ExploreEnv(maze_side_m=50.0)
    assert env.possible_agents == ["robot_0", "robot_1", "robot_2"] and env.agents == []
    assert env.metadata["name"] == "guide_team_explore_v0"
    for agent in env.possible_agents:
        space = env.observation_space(agent)
        assert space is env.observation_space(agent) and env.action_space(agent) is env.action_space(agent)
        assert env.action_space(agent) == single.action_space
        for key, inner in single.observation_space.spaces.items():
            assert space[key] == inner  # the single robot's graph arrays, unchanged
        assert space["teammates"].shape == (MAX_ROBOTS - 1, len(TEAMMATE_COLUMNS))
    assert env.observation_space("robot_0") is not env.observation_space("robot_1")  # each agent seeds its own
    obs, infos = env.reset(seed=4)
    assert env.agents == env.possible_agents
    for agent in env.agents:
        assert env.observation_space(agent).contains(obs[agent])
        np.testing.assert_array_equal(infos[agent]["action_mask"], obs[agent]["action_mask"])


def test_a_fresh_maze_per_reset_seed_and_given_maps(small_maze):
    env = TeamExploreEnv(robots=2, maze_side_m=50.0)
    env.reset(seed=1)
    first = env.ground_truth.name
    env.reset(seed=1)
    assert env.ground_truth.name == first
    env.reset(seed=2)
    assert env.ground_truth.name != first and env.ground_truth.name.startswith("maze_")
    env.reset(seed=0, options={"map": small_maze, "starts": STARTS[:2]})
    assert env.ground_truth is small_maze
    assert [r.position for r in env.episode.robots] == STARTS[:2]
    with pytest.warns(UserWarning, match="reset options strats are not used"):
        env.reset(seed=0, options={"strats": STARTS[:2]})
    with pytest.raises(ValueError, match="options\\['map'\\] must be a GroundTruthMap"):
        env.reset(options={"map": "small.png"})


@pytest.mark.parametrize(
    "values, message",
    [
        ({"robots": 0}, "robots: must be a whole number in 1..8"),
        ({"robots": 9}, "robots: must be a whole number in 1..8"),
        ({"robots": 2, "starts": [(0, 0)]}, "starts gives 1 positions for 2 robots"),
        ({"comm_range_m": -1.0}, "comm_range_m: must be a finite number > 0"),
        ({"belief_image": True}, "belief_image is not offered"),
        ({"step_limit": 0}, "step_limit: must be a whole number >= 1"),
        ({"robot": 2}, "unknown parameter"),
    ],
)
def test_bad_parameters_fail_naming_them(values, message):
    with pytest.raises(ValueError, match=message):
        TeamExploreEnv(maze_side_m=50.0, **values)


# ---------------------------------------------------------------------------------- who acts
def test_one_robot_acts_per_step_and_the_others_can_only_stay():
    env = TeamExploreEnv(robots=3, maze_side_m=50.0)
    obs, infos = env.reset(seed=5)
    assert env.acting_agents == ["robot_0"]  # at time 0 the robots decide in number order
    rng = np.random.default_rng(5)
    deciders, steps = [], 0
    while env.agents:
        (acting,) = env.acting_agents
        deciders.append(acting)
        for agent in env.agents:
            assert obs[agent]["acting"] == (agent == acting) and infos[agent]["acting"] == (agent == acting)
            mask = obs[agent]["action_mask"]
            assert mask[STAY_SLOT] == 1  # waiting is always allowed
            if agent != acting:
                assert mask.sum() == 1
        assert obs[acting]["action_mask"].sum() > 1  # moves known to be free, beside waiting
        obs, _, _, _, infos = env.step(masked_random_actions(env, obs, rng))
        steps += 1
    assert deciders[:3] == ["robot_0", "robot_1", "robot_2"]
    assert len(set(deciders)) == 3 and steps == len(deciders)


def test_the_others_actions_are_ignored():
    """Two runs from one seed, the acting robot choosing alike; in one the others send masked actions."""
    runs = []
    for noisy in (False, True):
        env = TeamExploreEnv(robots=3, maze_side_m=50.0)
        obs, _ = env.reset(seed=6)
        rng, noise = np.random.default_rng(6), np.random.default_rng(60)
        rewards = []
        while env.agents:
            actions = {agent: env.stay_action(agent) for agent in env.agents}
            if noisy:
                actions = {agent: int(noise.integers(env.action_count)) for agent in env.agents}
            (acting,) = env.acting_agents
            actions[acting] = int(rng.choice(np.flatnonzero(obs[acting]["action_mask"])))
            obs, reward, _, _, infos = env.step(actions)
            rewards.append(reward)
            assert not any(info["invalid_action"] for info in infos.values())
        runs.append((env.episode.rows, rewards))
    assert runs[0] == runs[1]


def test_the_acting_robots_mask_is_the_motion_rule_on_its_own_belief(small_maze):
    """Under a range each robot holds its own belief: a neighbour slot is valid for the acting robot
    exactly when the segment there is known free in that robot's belief."""
    env = TeamExploreEnv(robots=3, starts=STARTS, comm_range_m=6.0)
    obs, _ = env.reset(seed=0, options={"map": small_maze})
    d, checked = env.protocol.node_resolution, 0

    def check(env: TeamExploreEnv) -> None:
        nonlocal checked
        for agent in env.acting_agents:
            k = env.possible_agents.index(agent)
            robot, known = env.episode.robots[k], env.episode.beliefs[k].grid == FREE
            mask = env.action_masks(agent)
            for slot, (dx, dy) in enumerate(SLOT_OFFSETS):
                if slot == STAY_SLOT:
                    continue
                try:
                    cell = lattice_cell(
                        env.ground_truth, env.protocol, (robot.position[0] + dx * d, robot.position[1] + dy * d)
                    )
                    free = bool(known[cell[1], cell[0]]) and segment_is_known_free(known, robot.cell, cell)
                except MotionError:
                    free = False
                assert mask[slot] == free, (agent, slot)
            checked += 1

    drive(env, obs, "uncoordinated_nearest_frontier", check=check)
    assert checked > 20


def test_a_masked_action_makes_the_robot_wait_at_a_penalty():
    env = TeamExploreEnv(robots=2, maze_side_m=50.0)
    obs, _ = env.reset(seed=7)
    masked = int(np.flatnonzero(obs["robot_0"]["action_mask"] == 0)[0])
    _, rewards, _, _, infos = env.step({"robot_0": masked, "robot_1": STAY_SLOT})
    assert infos["robot_0"]["invalid_action"] and not infos["robot_1"]["invalid_action"]
    assert rewards["robot_0"] == pytest.approx(-env.config.invalid_action_penalty + infos["robot_0"]["reward_area"])
    assert infos["robot_0"]["reward_invalid"] == -env.config.invalid_action_penalty
    robot = env.episode.robots[0]
    assert robot.waiting and robot.heading is None and robot.moves == 0
    with pytest.raises(ValueError, match="outside"):
        env.step({"robot_0": 0, "robot_1": env.action_count})  # robot_1 acts now
    with pytest.raises(ValueError, match="robot_1 acts at this step"):
        env.step({"robot_0": 0})


# ---------------------------------------------------------------------------------- team episodes
@pytest.mark.parametrize("planner", ["uncoordinated_nearest_frontier", "uncoordinated_greedy_utility"])
@pytest.mark.parametrize("comm_range_m", [None, 12.0])
def test_a_planner_through_the_environment_is_run_team_episode(small_maze, planner, comm_range_m):
    reference = run_team_episode(
        small_maze, make_team_planner(planner), Protocol(), robots=3, starts=STARTS, comm_range_m=comm_range_m
    )
    env = TeamExploreEnv(robots=3, starts=STARTS, comm_range_m=comm_range_m)
    obs, _ = env.reset(seed=0, options={"map": small_maze})
    result = drive(env, obs, planner)
    assert reference.complete and result.complete and not result.failure
    assert result.rows == reference.rows  # every arrival, its robot and its time
    assert result.merges == reference.merges
    assert result.makespan_m == reference.makespan_m
    assert result.robot_distance_m == reference.robot_distance_m
    assert result.coverage == reference.coverage
    if comm_range_m is not None:
        assert reference.merges  # the robots parted and met again


def test_masked_random_agents_finish_with_consistent_rewards():
    env = TeamExploreEnv(robots=3, maze_side_m=50.0)
    rng = np.random.default_rng(8)
    for seed in (8, 9):
        obs, _ = env.reset(seed=seed)
        cell_area = env.protocol.cell_size**2
        known_at_start = env.episode.union.free_count
        totals = {agent: {"area": 0.0, "distance": 0.0, "bonus": 0.0, "reward": 0.0} for agent in env.agents}
        while env.agents:
            obs, rewards, terminated, truncated, infos = env.step(masked_random_actions(env, obs, rng))
            for agent, info in infos.items():
                parts = [info[f"reward_{part}"] for part in ("area", "distance", "bonus", "invalid")]
                assert rewards[agent] == pytest.approx(sum(parts))
                assert info["reward_area"] == pytest.approx(env.config.area_weight * info["new_area_m2"])
                assert info["reward_distance"] == pytest.approx(-env.config.distance_weight * info["step_distance_m"])
                assert not info["invalid_action"]
                for part, value in (
                    ("area", info["new_area_m2"]),
                    ("distance", info["step_distance_m"]),
                    ("bonus", info["reward_bonus"]),
                    ("reward", rewards[agent]),
                ):
                    totals[agent][part] += value
        ended = next(iter(terminated))
        assert terminated[ended] == env.episode.complete and truncated[ended] != terminated[ended]
        assert env.episode.complete  # random masked robots do explore a 50 m maze within the limits
        # The area terms split the team's new knowledge between the robots whose scans found it ...
        new_area = (env.episode.union.free_count - known_at_start) * cell_area
        assert sum(t["area"] for t in totals.values()) == pytest.approx(new_area)
        # ... the distance terms are each robot's finished moves, and every robot gets the bonus once.
        for k, agent in enumerate(env.possible_agents):
            assert totals[agent]["distance"] == pytest.approx(env.episode.robots[k].travelled)
            assert totals[agent]["bonus"] == env.config.completion_bonus
        assert all(t["area"] > 0 for t in totals.values())


def test_truncation_at_the_step_limit_and_at_the_robots_move_limit():
    env = TeamExploreEnv(robots=2, maze_side_m=50.0, step_limit=5)
    obs, _ = env.reset(seed=3)
    rng = np.random.default_rng(3)
    for step in range(5):
        obs, _, terminated, truncated, _ = env.step(masked_random_actions(env, obs, rng))
        assert not any(terminated.values()) and all(truncated.values()) == (step == 4)
    assert env.agents == [] and env.failure == "environment step limit (5 steps) reached"
    assert env.acting_agents == [] and all(obs[agent]["action_mask"].sum() == 1 for agent in obs)
    with pytest.raises(RuntimeError, match="call reset"):
        env.step({})
    env = TeamExploreEnv(robots=2, maze_side_m=50.0, max_steps=3)  # each robot stops after three moves
    obs, _ = env.reset(seed=3)
    while env.agents:
        actions = masked_random_actions(env, obs, rng)
        for agent in env.acting_agents:  # a move, never a wait
            mask = obs[agent]["action_mask"] & (np.arange(env.action_count) != STAY_SLOT)
            actions[agent] = int(rng.choice(np.flatnonzero(mask)))
        obs, _, terminated, truncated, _ = env.step(actions)
    assert all(truncated.values()) and not any(terminated.values())
    assert [r.moves for r in env.episode.robots] == [3, 3] and env.failure.startswith("step limit")


def test_a_waiting_robot_asks_again_after_the_next_arrival(small_maze):
    """run_team_episode's order: a robot that waits while nobody moves asks again once a teammate
    departs, at that teammate's arrival but after it; one that waits while a teammate moves, likewise."""
    env = TeamExploreEnv(robots=2, starts=STARTS[:2])
    obs, _ = env.reset(seed=0, options={"map": small_maze})

    def move(agent: str) -> int:
        mask = obs[agent]["action_mask"] & (np.arange(env.action_count) != STAY_SLOT)
        return int(np.flatnonzero(mask)[0])

    deciders = [(env.acting_agents[0], env.episode.time)]
    for chooser in ("robot_0", "robot_1", "robot_1", "robot_0", "robot_1"):
        assert env.acting_agents == [chooser]
        action = env.stay_action(chooser) if chooser == "robot_0" else move(chooser)
        actions = {agent: action if agent == chooser else env.stay_action(agent) for agent in env.agents}
        obs, _, _, _, _ = env.step(actions)
        deciders.append((env.acting_agents[0], env.episode.time))
    first, second = env.episode.rows[2][0], env.episode.rows[3][0]  # robot_1's two arrivals
    assert deciders == [
        ("robot_0", 0.0),
        ("robot_1", 0.0),
        ("robot_1", first),
        ("robot_0", first),
        ("robot_1", second),
        ("robot_0", second),
    ]


def test_every_robot_waiting_ends_the_episode():
    env = TeamExploreEnv(robots=2, maze_side_m=50.0)
    env.reset(seed=3)
    _, _, terminated, truncated, infos = env.step({"robot_0": STAY_SLOT, "robot_1": STAY_SLOT})
    assert env.acting_agents == ["robot_1"] and env.agents
    _, _, terminated, truncated, infos = env.step({"robot_0": STAY_SLOT, "robot_1": STAY_SLOT})
    assert all(terminated.values()) and not any(truncated.values()) and env.agents == []
    assert infos["robot_0"]["failure"] == "no reachable target left for any robot" and not env.episode.complete


# ---------------------------------------------------------------------------------- communication range
def test_with_a_range_each_robot_observes_its_own_belief_and_hears_teammates_when_near(small_maze):
    lattices_checked = []

    def check(env: TeamExploreEnv) -> None:
        for k, agent in enumerate(env.agents):
            # Each robot's lattice graph is the one its own belief makes.
            fresh = LatticeGraph(LatticeSpec.for_map(env.ground_truth, env.protocol))
            fresh.update(env.episode.beliefs[k].grid, None)
            np.testing.assert_array_equal(env.lattice(agent).node_state, fresh.node_state)
            np.testing.assert_array_equal(env.lattice(agent).edge_valid, fresh.edge_valid)
            np.testing.assert_array_equal(env.lattice(agent).utility, fresh.utility)
        lattices_checked.append(len({id(env.lattice(agent)) for agent in env.agents}))

    env = TeamExploreEnv(robots=3, starts=STARTS, comm_range_m=6.0)
    obs, _ = env.reset(seed=0, options={"map": small_maze})
    drive(env, obs, "uncoordinated_nearest_frontier", check=check)
    assert set(lattices_checked) == {3}  # one graph per robot all along

    # At the start robots 0 and 1 stand 4 m apart, robot 2 4 m from robot 0: all within 6 m.
    obs, _ = env.reset(seed=0, options={"map": small_maze, "starts": [(0.0, 0.0), (0.0, 4.0), (12.0, 0.0)]})
    teammates = obs["robot_0"]["teammates"]
    scale = env.graph_config.position_scale_nodes * env.protocol.node_resolution
    np.testing.assert_allclose(teammates[0, :4], [1.0, 1.0, 0.0, 4.0 / scale])  # robot_1, in range
    np.testing.assert_allclose(teammates[1, :4], [1.0, 0.0, 12.0 / scale, 0.0])  # robot_2, out of range
    assert not teammates[2:].any()  # padding for the robots a team of three lacks
    beliefs = env.episode.beliefs
    assert (beliefs[0].grid == beliefs[1].grid).all() and not (beliefs[0].grid == beliefs[2].grid).all()
    assert obs["robot_0"]["node_mask"].sum() != obs["robot_2"]["node_mask"].sum()

    # With full communication the team shares one belief and one graph, and every robot hears every other.
    env = TeamExploreEnv(robots=3, starts=[(0.0, 0.0), (0.0, 4.0), (12.0, 0.0)])
    obs, _ = env.reset(seed=0, options={"map": small_maze})
    assert len({id(env.lattice(agent)) for agent in env.agents}) == 1
    assert (obs["robot_0"]["teammates"][:2, 1] == 1.0).all()


def stood_on(env: TeamExploreEnv, robots) -> set[int]:
    """The lattice nodes the episode's rows so far put any of `robots` on."""
    lattice = env.lattice(env.possible_agents[0])
    return {lattice.nearest_node((x, y)) for _, robot, x, y in env.episode.rows if robot in robots}


@pytest.mark.parametrize("comm_range_m", [None, 6.0])
def test_robots_that_talk_share_the_nodes_stood_on(small_maze, comm_range_m):
    apart = []

    def check(env: TeamExploreEnv) -> None:
        everyone = range(len(env.possible_agents))
        for k, agent in enumerate(env.agents):
            known = set(np.flatnonzero(env.visited(agent)).tolist())
            assert stood_on(env, [k]) <= known <= stood_on(env, everyone)
            for j in everyone:
                if env.episode.connected[k][j]:
                    np.testing.assert_array_equal(env.visited(agent), env.visited(env.possible_agents[j]))
            apart.append(known != stood_on(env, everyone))

    env = TeamExploreEnv(robots=3, starts=STARTS, comm_range_m=comm_range_m)
    obs, _ = env.reset(seed=0, options={"map": small_maze})
    drive(env, obs, "uncoordinated_nearest_frontier", check=check)
    assert any(apart) == (comm_range_m is not None)  # under a range some visits are not heard of at once


def test_teammates_targets_are_heard(small_maze):
    env = TeamExploreEnv(robots=2, starts=STARTS[:2])
    obs, _ = env.reset(seed=0, options={"map": small_maze})
    assert not obs["robot_1"]["teammates"][0, 4]  # robot_0 has not decided yet
    action = int(np.flatnonzero(obs["robot_0"]["action_mask"] & (np.arange(env.action_count) != STAY_SLOT))[0])
    obs, _, _, _, _ = env.step({"robot_0": action, "robot_1": STAY_SLOT})
    target = env.episode.robots[0].target
    scale = env.graph_config.position_scale_nodes * env.protocol.node_resolution
    here = env.episode.robots[1].position
    np.testing.assert_allclose(
        obs["robot_1"]["teammates"][0, 4:],
        [1.0, (target[0] - here[0]) / scale, (target[1] - here[1]) / scale],
        rtol=1e-6,
    )


# ---------------------------------------------------------------------------------- the single robot's terms
def test_a_team_of_one_observes_and_is_rewarded_as_explore_v0(small_maze_path):
    """Both environments driven alike (nearest_frontier's moves, every other one replaced by a random
    valid move): the same graph arrays, masks and reward terms at every step, to completion."""
    single = ExploreEnv(map=str(small_maze_path))
    team = TeamExploreEnv(robots=1, map=str(small_maze_path))
    single_obs, _ = single.reset(seed=0)
    team_obs, _ = team.reset(seed=0)
    planner = make_planner("nearest_frontier")
    planner.reset(single.episode.map, Protocol(), 0)
    rng = np.random.default_rng(1)
    while True:
        obs = team_obs["robot_0"]
        for key in single_obs:
            if key == "action_mask":  # the team's robot may always wait; Explore-v0's only when stuck
                moves = obs[key].copy()
                moves[STAY_SLOT] = 0
                np.testing.assert_array_equal(moves, single_obs[key])
            else:
                np.testing.assert_array_equal(obs[key], single_obs[key], err_msg=key)
        waypoints = planner.plan(single.episode.observe())
        if waypoints and rng.random() < 0.5:
            action = single.action_for_waypoint(waypoints[0])
        else:
            action = int(rng.choice(np.flatnonzero(single_obs["action_mask"])))
        single_obs, reward, terminated, truncated, info = single.step(action)
        team_obs, team_reward, team_terminated, _, team_info = team.step({"robot_0": action})
        for key in ("reward_area", "reward_distance", "reward_bonus", "new_area_m2", "step_distance_m"):
            assert team_info["robot_0"][key] == pytest.approx(info[key]), key
        assert team_reward["robot_0"] == pytest.approx(reward)
        if terminated or truncated:
            assert team_terminated["robot_0"] == terminated
            break
        assert team.agents == ["robot_0"]
    assert info["complete"] and team_info["robot_0"]["complete"]
    assert team_info["robot_0"]["reward_bonus"] == info["reward_bonus"] > 0


# ---------------------------------------------------------------------------------- docs/teams.md
def test_the_docs_random_team_runs_as_written():
    doc = (ROOT / "docs" / "teams.md").read_text()
    section = doc.split("## A PettingZoo environment\n", 1)[1].split("\n## ", 1)[0]
    *_, example = re.findall(r"```python\n(.*?)```", section, flags=re.S)
    assert "action_mask" in example and "env.step(actions)" in example
    printed = io.StringIO()
    with contextlib.redirect_stdout(printed):
        exec(compile(example, "docs/teams.md", "exec"), {"__name__": "docs_example"})
    line = printed.getvalue()
    assert re.fullmatch(
        r"maze_\d+: (complete|.+ reached|no reachable target left for any robot) at \d+ m; "
        r"robot_0 -?[\d.]+, robot_1 -?[\d.]+, robot_2 -?[\d.]+\n",
        line,
    ), line
