"""guide/Explore-v0: the Gymnasium checks, the simulator as referee, the planners' observation, rewards, maps."""

from __future__ import annotations

import math
import os
import re
import subprocess
import sys
import warnings

import gymnasium
import numpy as np
import pytest
from conftest import write_ros_map
from gymnasium.utils.env_checker import check_env
from import_graph import ROOT

import pipeline  # noqa: F401  (registers the id)
from pipeline.envs import ENV_ID, ExploreEnv, ExploreEnvConfig
from pipeline.envs.map_sources import maze_from_image
from pipeline.planners import make_planner
from pipeline.planners.baselines.frontier import GreedyUtilityPlanner
from pipeline.prediction.global_graph import GlobalGraph, GlobalGraphConfig
from pipeline.prediction.graph_observation import observe
from pipeline.prediction.observed_graph import SLOT_OFFSETS, STAY_SLOT, slot_of_offset
from pipeline.world.maps import load_map, load_maze_png
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import Episode, MotionError, run_episode


def drive(env: ExploreEnv, planner, protocol: Protocol, target: bool = False) -> tuple[dict, list[dict]]:
    """Run `planner` through the environment: each decision's first waypoint (or, with `target`, its
    last) becomes the action. Returns the last info and every step's observation."""
    episode = env.episode
    planner.reset(episode.map, protocol, 0)
    observations, info = [], {}
    while True:
        waypoints = planner.plan(episode.observe())
        if not waypoints:
            return info, observations
        obs, _, terminated, truncated, info = env.step(env.action_for_waypoint(waypoints[-1 if target else 0]))
        observations.append(obs)
        assert not info["invalid_action"]
        if terminated or truncated:
            return info, observations


class WholePathGreedy(GreedyUtilityPlanner):
    """greedy_utility that hands over its whole path to a target, not just the path's first node: its
    best target (`rank` 0) or another of its ranking (-1: the worst, often far away)."""

    def __init__(self, rank: int = 0):
        super().__init__()
        self.rank = rank

    def plan(self, observation):
        pred, ranked = self.ranked_targets(observation)
        if ranked.size == 0:
            return []
        path = self.graph.path_from_predecessors(pred, int(ranked[self.rank]))
        return self.waypoints_along(path, len(path))


# ---------------------------------------------------------------------------------- gymnasium
def test_the_id_is_registered_and_makes_an_environment_without_torch(small_maze_path):
    assert ENV_ID in gymnasium.registry
    code = (
        "import sys, gymnasium, pipeline\n"
        f"env = gymnasium.make('{ENV_ID}', map={str(small_maze_path)!r})\n"
        "env.reset(seed=0); env.step(int(env.unwrapped.action_masks().argmax()))\n"
        "print('torch' in sys.modules)"
    )
    done = subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "PYTHONPATH": str(ROOT)},
    )
    assert done.returncode == 0, done.stderr[-2000:]
    assert done.stdout.split()[-1] == "False"


@pytest.mark.parametrize("options", [{}, {"action": "node"}, {"belief_image": True}])
def test_the_gymnasium_checker_passes(small_maze_path, options):
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # the checker's warnings too
        env = gymnasium.make(ENV_ID, map=str(small_maze_path), **options)
        check_env(env.unwrapped)


def test_generated_mazes_pass_the_checker():
    check_env(gymnasium.make(ENV_ID, map="maze", maze_side_m=50.0, max_nodes=64).unwrapped)


def test_it_runs_in_an_async_vector_env(small_maze_path, generated_maze_dir):
    envs = gymnasium.vector.AsyncVectorEnv(
        [
            lambda: gymnasium.make(ENV_ID, map=str(small_maze_path)),
            lambda: gymnasium.make(ENV_ID, map=str(generated_maze_dir)),
        ]
    )
    try:
        obs, _ = envs.reset(seed=3)
        assert obs["features"].shape == (2, 320, 7) and obs["action_mask"].shape == (2, 25)
        rng = np.random.default_rng(0)
        for _ in range(4):
            actions = [int(rng.choice(np.flatnonzero(mask))) for mask in obs["action_mask"]]
            obs, rewards, terminated, truncated, info = envs.step(np.array(actions))
            assert not info["invalid_action"].any()
            assert (info["steps"] >= 1).all()
    finally:
        envs.close()


# ---------------------------------------------------------------------------------- the simulator's episodes
@pytest.fixture(scope="module")
def maps(small_maze_path, generated_maze_dir):
    return [small_maze_path, sorted(generated_maze_dir.glob("*.png"))[0]]


def test_greedy_through_the_environment_is_run_episode(maps):
    for path in maps:
        reference = run_episode(load_map(path), make_planner("greedy_utility"), Protocol())
        env = ExploreEnv(map=str(path))
        env.reset(seed=0)
        info, _ = drive(env, make_planner("greedy_utility"), Protocol())
        assert reference.complete and info["complete"]
        assert info["trajectory"] == reference.trajectory
        assert info["distance"] == pytest.approx(reference.distance_m, abs=1e-9)
        assert info["waypoints"] == info["steps"] == reference.steps


def test_node_actions_drive_to_greedy_choices_as_run_episode_does(maps):
    multi_waypoint_actions = 0
    for path in maps:
        # Its next waypoint as a node action: the same episode as greedy_utility's.
        reference = run_episode(load_map(path), make_planner("greedy_utility"), Protocol())
        env = ExploreEnv(map=str(path), action="node")
        env.reset(seed=0)
        info, _ = drive(env, make_planner("greedy_utility"), Protocol())
        assert info["trajectory"] == reference.trajectory
        assert info["distance"] == pytest.approx(reference.distance_m, abs=1e-9)
        # Its target as a node action: the whole shortest path, sensed at every node, as run_episode moves
        # through a planner's waypoints.
        for rank in (0, -1):
            reference = run_episode(load_map(path), WholePathGreedy(rank), Protocol())
            env.reset(seed=0)
            info, _ = drive(env, WholePathGreedy(rank), Protocol(), target=True)
            assert reference.complete and info["complete"]
            assert info["trajectory"] == reference.trajectory
            assert info["distance"] == pytest.approx(reference.distance_m, abs=1e-9)
            multi_waypoint_actions += info["waypoints"] - info["steps"]
    assert multi_waypoint_actions > 0  # some targets lay several waypoints away


@pytest.mark.parametrize("max_nodes, max_neighbors", [(320, 25), (24, 4)])
def test_the_observation_is_the_dare_planners_observed_graph(maps, max_nodes, max_neighbors):
    """The arrays read off the lattice graph are `observe` on a GlobalGraph without predictions, step for
    step (and with rows and neighbour slots cut short)."""
    env = ExploreEnv(map=str(maps[1]), max_nodes=max_nodes, max_neighbors=max_neighbors)
    obs, _ = env.reset(seed=0)
    planner = make_planner("greedy_utility")
    planner.reset(env.episode.map, Protocol(), 0)
    config = GlobalGraphConfig(max_nodes=max_nodes, use_region_evaluation=False)
    truncated_rows = dropped_rows = 0
    for _ in range(40):
        graph = GlobalGraph(env.lattice, config)
        graph.update(env.lattice.belief, env.episode.position, None, env.visited)
        expected = observe(graph, env.episode.position, max_neighbors)
        np.testing.assert_array_equal(obs["features"], expected.features)
        np.testing.assert_array_equal(obs["node_mask"].astype(bool), expected.node_mask)
        np.testing.assert_array_equal(obs["neighbors"], expected.neighbors)
        assert obs["robot"] == expected.robot
        truncated_rows += int(((expected.neighbors >= 0).sum(axis=1) == max_neighbors).sum())
        dropped_rows += int(graph.node_count > max_nodes)
        waypoints = planner.plan(env.episode.observe())
        if not waypoints:
            break
        obs, _, terminated, truncated, _ = env.step(env.action_for_waypoint(waypoints[0]))
        if terminated or truncated:
            break
    if max_neighbors < 24:
        assert truncated_rows > 0 and dropped_rows > 0  # both cut-offs were exercised


def test_the_mask_is_the_simulators_motion_rule(maps):
    """At every step of an episode, each neighbour slot is valid exactly when Episode.move accepts it."""
    ground_truth = load_map(maps[0])
    env = ExploreEnv(map=str(maps[0]))
    env.reset(seed=0)
    planner = make_planner("nearest_frontier")
    planner.reset(ground_truth, Protocol(), 0)
    d = Protocol().node_resolution
    for step in range(12):
        mask = env.action_masks()
        assert not mask[STAY_SLOT]
        x, y = env.episode.position
        for slot, (dx, dy) in enumerate(SLOT_OFFSETS):
            if slot == STAY_SLOT:
                continue
            referee = Episode(ground_truth, Protocol())
            for waypoint in env.episode.trajectory[1:]:
                referee.move(waypoint)
            try:
                referee.move((x + dx * d, y + dy * d))
                accepted = True
            except MotionError:
                accepted = False
            assert mask[slot] == accepted, (step, slot)
        waypoints = planner.plan(env.episode.observe())
        if not waypoints:
            break
        *_, terminated, truncated, _ = env.step(env.action_for_waypoint(waypoints[0]))
        if terminated or truncated:
            break


def test_a_masked_action_leaves_the_robot_and_costs_the_penalty(small_maze_path):
    env = ExploreEnv(map=str(small_maze_path), invalid_action_penalty=2.5, max_steps=3)
    obs, info = env.reset(seed=0)
    masked = int(np.flatnonzero(~env.action_masks())[0])
    for step in (1, 2):
        after, reward, terminated, truncated, info = env.step(masked)
        assert info["invalid_action"] and reward == -2.5 and info["reward_invalid"] == -2.5
        assert info["trajectory"] == [(0.0, 0.0)] and info["distance"] == 0.0 and info["steps"] == step
        assert not terminated and not truncated
        for key in obs:
            np.testing.assert_array_equal(after[key], obs[key])
    *_, terminated, truncated, info = env.step(masked)
    assert truncated and not terminated and info["steps"] == 3  # invalid steps count toward max_steps
    with pytest.raises(RuntimeError, match="reset"):
        env.step(masked)
    env.reset(seed=0)
    for bad in (25, -1, 2.0, "3"):
        with pytest.raises(ValueError, match="action"):
            env.step(bad)


def test_a_robot_with_no_move_can_only_stay_which_ends_the_episode(tmp_path):
    free = np.zeros((40, 40), dtype=np.uint8)
    free[10:13, 10:13] = 1  # a pocket smaller than one lattice spacing
    free[25:38, 2:38] = 1  # free space the robot can never reach, so the map is not complete at the start
    np.save(tmp_path / "pocket.npy", free)
    env = ExploreEnv(map=str(tmp_path / "pocket.npy"), start=(11, 11), done_unknown_cells=10)
    obs, _ = env.reset(seed=0)
    assert np.flatnonzero(obs["action_mask"]).tolist() == [STAY_SLOT]
    _, reward, terminated, truncated, info = env.step(STAY_SLOT)
    assert terminated and not truncated and info["stuck"] and not info["complete"] and reward == 0.0


# ---------------------------------------------------------------------------------- reward, done rule, truncation
def test_reward_parts_sum_and_the_episode_ends_by_the_done_rule(small_maze_path):
    weights = {"area_weight": 0.5, "distance_weight": 0.25, "completion_bonus": 7.0}
    env = ExploreEnv(map=str(small_maze_path), **weights)
    env.reset(seed=0)
    cell_area = Protocol().cell_size ** 2
    planner = make_planner("greedy_utility")
    planner.reset(env.episode.map, Protocol(), 0)
    bonuses = []
    while True:
        free_before, distance_before = env.episode.belief.free_count, env.episode.distance
        _, reward, terminated, truncated, info = env.step(
            env.action_for_waypoint(planner.plan(env.episode.observe())[0])
        )
        parts = [info[k] for k in ("reward_area", "reward_distance", "reward_bonus", "reward_invalid")]
        assert reward == pytest.approx(sum(parts))
        assert info["new_area_m2"] == pytest.approx((env.episode.belief.free_count - free_before) * cell_area)
        assert info["reward_area"] == pytest.approx(0.5 * info["new_area_m2"])
        assert info["step_distance_m"] == pytest.approx(env.episode.distance - distance_before)
        assert info["reward_distance"] == pytest.approx(-0.25 * info["step_distance_m"]) and info["step_distance_m"] > 0
        bonuses.append(info["reward_bonus"])
        assert terminated == env.episode.complete and not truncated
        if terminated:
            break
    assert bonuses[-1] == 7.0 and not any(bonuses[:-1])
    assert info["complete"] and info["explored_share"] == env.episode.explored_ratio
    unseen = env.episode.map.free_cell_count - env.episode.belief.free_count
    assert unseen <= Protocol().done_unknown_cells


def test_truncation_at_max_steps_and_at_max_waypoints(small_maze_path):
    env = ExploreEnv(map=str(small_maze_path), max_steps=2)
    env.reset(seed=0)
    planner = make_planner("greedy_utility")
    planner.reset(env.episode.map, Protocol(), 0)
    *_, terminated, truncated, _ = env.step(env.action_for_waypoint(planner.plan(env.episode.observe())[0]))
    assert not terminated and not truncated
    *_, terminated, truncated, info = env.step(env.action_for_waypoint(planner.plan(env.episode.observe())[0]))
    assert truncated and not terminated and info["steps"] == 2
    # A node action stops at max_steps waypoints, as run_episode stops a planner's waypoints.
    env = ExploreEnv(map=str(small_maze_path), action="node", max_steps=1)
    obs, _ = env.reset(seed=0)
    _, predecessors = env.lattice.shortest_paths(env.lattice.nearest_node(env.episode.position))
    hops = [
        len(env.lattice.path_from_predecessors(predecessors, int(env.row_nodes[row]))) - 1
        for row in np.flatnonzero(obs["action_mask"])
    ]
    far = int(np.flatnonzero(obs["action_mask"])[int(np.argmax(hops))])
    assert max(hops) >= 2
    *_, terminated, truncated, info = env.step(far)
    assert truncated and not terminated and info["steps"] == 1 and info["waypoints"] == 1


# ---------------------------------------------------------------------------------- maps and parameters
def test_a_generated_maze_per_reset_seed(tmp_path):
    env = ExploreEnv(map="maze", maze_side_m=50.0, max_nodes=64)
    first, info_a = env.reset(seed=4)
    trajectory_a = env.step(int(np.flatnonzero(first["action_mask"])[0]))[4]["trajectory"]
    again, info_b = env.reset(seed=4)
    trajectory_b = env.step(int(np.flatnonzero(again["action_mask"])[0]))[4]["trajectory"]
    assert info_a["map_name"] == info_b["map_name"] and trajectory_a == trajectory_b
    np.testing.assert_array_equal(first["features"], again["features"])
    other, info_c = env.reset(seed=5)
    assert info_c["map_name"] != info_a["map_name"]
    # The grid is the one load_maze_png reads from that maze's PNG.
    seed = int(info_c["map_name"].removeprefix("maze_"))
    path = write_maze_png(
        generate_maze(MazeConfig(side_m=(50.0, 50.0)), np.random.default_rng(seed)), tmp_path / "m.png"
    )
    from_file = load_maze_png(path)
    np.testing.assert_array_equal(env.episode.map.free, from_file.free)
    assert env.episode.map.start_cell == from_file.start_cell
    image = generate_maze(MazeConfig(side_m=(50.0, 50.0)), np.random.default_rng(seed))
    assert maze_from_image(image, 0.4, "m").start_cell == from_file.start_cell


def test_a_folder_gives_one_map_per_reset_by_seed(generated_maze_dir):
    env = ExploreEnv(map=str(generated_maze_dir))
    names = {seed: env.reset(seed=seed)[1]["map_name"] for seed in range(20)}
    assert names == {seed: env.reset(seed=seed)[1]["map_name"] for seed in range(20)}
    assert set(names.values()) == {p.stem for p in generated_maze_dir.glob("*.png")}


def test_ros_and_npy_maps_load(tmp_path, small_maze):
    free = np.zeros((60, 80), dtype=bool)
    free[5:55, 5:75] = True
    yaml_path = write_ros_map(tmp_path, free, 0.2, (3.0, 3.0), name="hall")
    env = ExploreEnv(map=str(yaml_path), node_resolution=2.0, sensor_range=6.0, utility_range=3.0)
    obs, info = env.reset(seed=0)
    assert info["map_name"] == "hall" and env.episode.protocol.cell_size == 0.2  # the map's resolution
    assert obs["action_mask"].sum() > 0
    np.save(tmp_path / "grid.npy", small_maze.free.astype(np.uint8))
    env = ExploreEnv(map=str(tmp_path / "grid.npy"), start=small_maze.start_cell)
    env.reset(seed=0)
    info, _ = drive(env, make_planner("greedy_utility"), Protocol())
    reference = run_episode(small_maze, make_planner("greedy_utility"), Protocol())
    assert info["trajectory"] == reference.trajectory
    with pytest.raises(ValueError, match="map: .*grid.npy.*start"):
        ExploreEnv(map=str(tmp_path / "grid.npy"))


def test_the_belief_image_option(small_maze_path, small_maze):
    env = ExploreEnv(map=str(small_maze_path), belief_image=True, belief_shape=(200, 150), render_mode="rgb_array")
    obs, _ = env.reset(seed=0)
    rows, cols = small_maze.shape
    assert obs["belief"].shape == (200, 150) and obs["belief"].dtype == np.uint8
    np.testing.assert_array_equal(obs["belief"][:rows, :cols], env.episode.belief.grid)
    assert (obs["belief"][rows:] == 0).all() and (obs["belief"][:, cols:] == 0).all()
    assert tuple(obs["robot_cell"]) == small_maze.start_cell
    assert env.render().shape == (rows, cols, 3)
    assert ExploreEnv(map=str(small_maze_path), belief_image=True).observation_space["belief"].shape == small_maze.shape


def test_protocol_fields_are_parameters(small_maze_path):
    env = ExploreEnv(map=str(small_maze_path), protocol=Protocol(node_resolution=2.0, max_steps=7))
    env.reset(seed=0)
    assert env.episode.protocol.node_resolution == 2.0 and env.config.max_steps == 7
    env.step(int(np.flatnonzero(env.action_masks())[0]))
    (x, y) = env.episode.position
    assert max(abs(x), abs(y)) <= 4.0 and (x, y) != (0.0, 0.0)
    assert (
        gymnasium.make(ENV_ID, map=str(small_maze_path), sensor_range=12.0).unwrapped.config.protocol().sensor_range
        == 12.0
    )


@pytest.mark.parametrize(
    "values, parameter",
    [
        ({"map": "no/such/map.png"}, "map"),
        ({"area_weight": -1.0}, "area_weight"),
        ({"distance_weight": float("nan")}, "distance_weight"),
        ({"completion_bonus": -2}, "completion_bonus"),
        ({"invalid_action_penalty": -0.1}, "invalid_action_penalty"),
        ({"max_steps": 0}, "max_steps"),
        ({"max_nodes": 0}, "max_nodes"),
        ({"max_neighbors": 0}, "max_neighbors"),
        ({"action": "teleport"}, "action"),
        ({"cell_size": -0.4}, "cell_size"),
        ({"maze_side_m": 12.0}, "maze_side_m"),
        ({"map": "maze", "start": (1, 2)}, "start"),
        ({"belief_shape": (10, 10)}, "belief_shape"),
        ({"belief_image": True, "belief_shape": (0, 10)}, "belief_shape"),
        ({"speed": 3}, "speed"),
    ],
)
def test_bad_parameters_fail_naming_the_parameter(values, parameter):
    with pytest.raises(ValueError, match=re.escape(parameter)):
        ExploreEnv(**values)


@pytest.mark.parametrize(
    "values, message",
    [
        ({"max_steps": 0}, "max_steps: must be a whole number >= 1, got 0"),
        ({"max_steps": 3.0}, "max_steps: must be a whole number >= 1, got 3.0"),
        ({"area_weight": -1.0}, "area_weight: must be a finite number >= 0, got -1.0"),
        ({"action": "teleport"}, "action: must be one of 'neighbour', 'node', got 'teleport'"),
        ({"belief_image": 1}, "belief_image: must be true or false, got 1"),
        ({"map": "x.png", "start": (1.0, math.nan)}, "start[1]: must be a finite number, got nan"),
        ({"belief_image": True, "belief_shape": (10, 10, 3)}, "belief_shape: must be two cell counts (rows, cols)"),
        ({"node_resolution": 0.2}, "node_resolution (0.2 m) must be at least one cell (0.4 m)"),
    ],
)
def test_a_bad_parameter_is_one_line_naming_it(values, message):
    with pytest.raises(ValueError) as error:
        ExploreEnvConfig.from_kwargs(**values)
    assert str(error.value).startswith(message) and "\n" not in str(error.value), str(error.value)
    assert ExploreEnvConfig.from_kwargs(map="x.png", start=np.array([1, 2])).start == (1.0, 2.0)


def test_bad_map_files_and_folders(tmp_path, small_maze_path):
    (tmp_path / "broken.png").write_bytes(b"not a png")
    with pytest.raises(ValueError, match="map: .*broken.png"):
        ExploreEnv(map=str(tmp_path / "broken.png"))
    with pytest.raises(ValueError, match="map: .*broken.png"):  # a folder's maps are read when it is made
        ExploreEnv(map=str(tmp_path))
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(ValueError, match="map: .*no map"):
        ExploreEnv(map=str(empty))
    with pytest.raises(ValueError, match="belief_shape"):
        ExploreEnv(map=str(small_maze_path), belief_image=True, belief_shape=(10, 10)).reset(seed=0)
    with pytest.raises(ValueError, match="either config"):
        ExploreEnv(config=ExploreEnvConfig(map=str(small_maze_path)), action="node")


def test_slot_offsets_are_row_major():
    assert [slot_of_offset(int(dx), int(dy)) for dx, dy in SLOT_OFFSETS] == list(range(25))
    assert tuple(SLOT_OFFSETS[STAY_SLOT]) == (0, 0) and tuple(SLOT_OFFSETS[0]) == (-2, -2)
    assert tuple(SLOT_OFFSETS[1]) == (-1, -2)
    with pytest.raises(ValueError, match="window"):
        slot_of_offset(3, 0)
