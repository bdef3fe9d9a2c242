"""The `drl` planner (pipeline/planners/baselines/drl.py): run by the simulator it decides as the
Gymnasium environment's agent does with the same policy; the shipped policy explores a maze;
a missing checkpoint and a policy trained at another protocol are reported."""

from __future__ import annotations

import warnings

import numpy as np
import pytest
import torch
from conftest import SMALL_MAZE, maze_from_blocks

from pipeline.envs.explore_env import ExploreEnv
from pipeline.models import defaults
from pipeline.models.configuration_drl import DRLPolicyConfig
from pipeline.models.modeling_drl import DRLPolicy, save_drl_policy
from pipeline.planners import make_planner
from pipeline.planners.baselines.drl import DRLPlanner
from pipeline.planners.wrapper import innermost
from pipeline.world.maps import list_maps, load_map
from pipeline.world.mazes import write_maze_png
from pipeline.world.protocol import Protocol, ProtocolMismatchWarning
from pipeline.world.simulator import run_episode

TINY = {"max_nodes": 32, "d_model": 16, "heads": 2, "encoder_layers": 1}


def fresh_policy(seed: int, **values) -> DRLPolicy:
    torch.manual_seed(seed)
    return DRLPolicy(DRLPolicyConfig(**{**TINY, **values}))


def env_episode(path, policy: DRLPolicy, protocol: Protocol) -> dict:
    """The environment's episode with `policy` choosing greedily: its last info."""
    env = ExploreEnv(
        map=str(path), protocol=protocol, max_nodes=policy.config.max_nodes, max_neighbors=policy.config.max_neighbors
    )
    obs, info = env.reset(seed=0)
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(policy.predict_action(obs))
        assert not info["invalid_action"]
        done = terminated or truncated
    env.close()
    return info


@pytest.fixture(scope="module")
def maps(small_maze_path, generated_maze_dir):
    return [small_maze_path, list_maps(generated_maze_dir)[0]]


@pytest.mark.parametrize(
    ("seed", "values", "protocol"),
    [
        (1, {"guidepost_prior": 0.0}, Protocol(max_steps=30)),  # a random pointer: loops back and forth
        (2, {}, Protocol(max_steps=30)),  # the default prior: partly follows the guidepost
        (3, {"guidepost_prior": 30.0}, Protocol(max_steps=60)),  # follows the guidepost to the end
        (4, {"max_neighbors": 6}, Protocol(max_steps=30, node_resolution=3.0, sensor_range=15.0)),
    ],
)
def test_the_planner_decides_as_the_environments_agent(maps, seed, values, protocol):
    policy = fresh_policy(seed, **values)
    for path in maps:
        planner = make_planner("drl", policy=policy, stall_steps=0)
        assert isinstance(innermost(planner), DRLPlanner) and innermost(planner).source == "injected drl policy"
        result = run_episode(load_map(path), planner, protocol)
        info = env_episode(path, policy, protocol)
        assert result.motion_violations == 0
        assert result.trajectory == info["trajectory"]
        assert result.distance_m == pytest.approx(info["distance"], abs=1e-9)
        assert result.complete == info["complete"]
        assert len(result.trajectory) > 10


def test_the_episodes_compared_are_not_trivial(maps):
    """The random pointer revisits nodes until the step limit; the guidepost-led one completes."""
    looping = run_episode(
        load_map(maps[0]),
        make_planner("drl", policy=fresh_policy(1, guidepost_prior=0.0), stall_steps=0),
        Protocol(max_steps=30),
    )
    assert len(looping.trajectory) == 31 and len(set(looping.trajectory)) < 31 and not looping.complete
    led = run_episode(
        load_map(maps[0]),
        make_planner("drl", policy=fresh_policy(3, guidepost_prior=30.0), stall_steps=0),
        Protocol(max_steps=60),
    )
    assert led.complete and len(set(led.trajectory)) == len(led.trajectory)


def test_a_checkpoint_is_loaded_and_decides_as_the_policy_saved(tmp_path, maps):
    policy = fresh_policy(5).eval()
    path = save_drl_policy(policy, tmp_path / "policy.pt", {"protocol": Protocol().to_dict()})
    protocol = Protocol(max_steps=25)
    from_file = run_episode(load_map(maps[1]), make_planner("drl", policy_file=str(path), stall_steps=0), protocol)
    injected = run_episode(load_map(maps[1]), make_planner("drl", policy=policy, stall_steps=0), protocol)
    assert from_file.trajectory == injected.trajectory
    assert str(path) in make_planner("drl", policy_file=str(path)).description


def test_the_shipped_policy_explores_a_generated_maze(generated_maze_dir, tmp_path, monkeypatch):
    assert defaults.SHIPPED_DRL.is_file()  # (conftest hides any models/ a dvc repro left)
    planner = make_planner("drl")
    assert innermost(planner).source == "drl policy (shipped)"
    for path in list_maps(generated_maze_dir):
        result = run_episode(load_map(path), planner, Protocol())
        assert result.complete, (path.name, result.failure)
        assert result.motion_violations == 0 and not result.failure


def test_the_pipelines_policy_comes_before_the_shipped_one(tmp_path, monkeypatch):
    path = save_drl_policy(fresh_policy(6), tmp_path / "models" / "drl" / "policy.pt")
    monkeypatch.setitem(defaults.MODEL_FILES, "drl", (path, defaults.MODEL_FILES["drl"][1]))
    assert innermost(make_planner("drl")).source == f"drl policy {path}"


def test_no_policy_anywhere_is_a_one_line_error(tmp_path, monkeypatch):
    monkeypatch.setitem(
        defaults.MODEL_FILES, "drl", (tmp_path / "a" / "policy.pt", (tmp_path / "b" / "planner_drl.pt",))
    )
    with pytest.raises(ValueError, match="no drl policy") as error:
        make_planner("drl")
    assert "\n" not in str(error.value)


def test_a_missing_checkpoint_is_a_one_line_error_naming_it(tmp_path):
    missing = tmp_path / "nowhere" / "policy.pt"
    with pytest.raises(ValueError, match="policy.pt: file not found") as error:
        make_planner("drl", policy_file=str(missing))
    assert str(missing) in str(error.value) and "\n" not in str(error.value)
    with pytest.raises(ValueError, match="a folder, not a file"):
        make_planner("drl", policy_file=str(tmp_path))


def test_a_checkpoint_that_is_not_a_drl_export_is_refused(tmp_path):
    torch.save({"format": "x"}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not a drl policy export"):
        make_planner("drl", policy_file=str(tmp_path / "other.pt"))


def test_a_policy_trained_at_another_protocol_warns_at_reset(tmp_path, small_maze):
    trained = Protocol(node_resolution=2.0, sensor_range=12.0)
    path = save_drl_policy(fresh_policy(7), tmp_path / "other_protocol.pt", {"protocol": trained.to_dict()})
    planner = make_planner("drl", policy_file=str(path))
    with pytest.warns(ProtocolMismatchWarning, match=r"node_resolution 2 -> 4.*sensor_range 12 -> 20"):
        planner.reset(small_maze, Protocol(), 0)
    # At its own protocol values (the cell size aside, which the graph does not depend on), no warning.
    with warnings.catch_warnings():
        warnings.simplefilter("error", ProtocolMismatchWarning)
        planner.reset(small_maze, Protocol(node_resolution=2.0, sensor_range=12.0, cell_size=0.2), 0)
        # An injected policy, and an export that records no protocol, have nothing to compare.
        make_planner("drl", policy=fresh_policy(7)).reset(small_maze, Protocol(node_resolution=2.0), 0)
        bare = save_drl_policy(fresh_policy(7), tmp_path / "bare.pt")
        make_planner("drl", policy_file=str(bare)).reset(small_maze, Protocol(node_resolution=2.0), 0)


# The small maze with two closed rooms no sensor reaches: it can never be complete.
ISLANDS = SMALL_MAZE[:8] + ["#..#...#.#", "######.###", "#.#...##.#", "##########"]


def test_it_stops_where_nothing_is_left_to_see_and_the_environment_wanders_on(tmp_path):
    """The planner ends the episode when no reachable unvisited node sees a frontier cell (the
    documented done rule); the environment, whose agent has no such action, goes on to its step
    limit: up to then the two decide alike."""
    path = tmp_path / "islands.png"
    write_maze_png(maze_from_blocks(ISLANDS), path)
    policy = fresh_policy(3, guidepost_prior=30.0)
    protocol = Protocol(max_steps=120)
    result = run_episode(load_map(path), make_planner("drl", policy=policy, stall_steps=0), protocol)
    info = env_episode(path, policy, protocol)
    assert not result.complete and result.failure == "no reachable target left"
    assert result.motion_violations == 0 and 20 < len(result.trajectory) < 120
    assert info["trajectory"][: len(result.trajectory)] == result.trajectory
    assert not info["complete"] and len(info["trajectory"]) == 121


def test_the_observed_graph_does_not_depend_on_the_region_size(small_maze_path):
    """The drl policy's observations, step for step, are the same at any region_size."""
    policy = fresh_policy(1, guidepost_prior=0.0)
    trajectories = []
    for region_size in (20.0, 8.0):
        env = ExploreEnv(map=str(small_maze_path), max_nodes=32, max_steps=30, region_size=region_size)
        obs, _ = env.reset(seed=0)
        seen = [obs]
        done = False
        while not done:
            obs, _, terminated, truncated, info = env.step(policy.predict_action(obs))
            seen.append(obs)
            done = terminated or truncated
        trajectories.append((seen, info["trajectory"]))
    (first, path_a), (second, path_b) = trajectories
    assert path_a == path_b and len(first) == len(second) == 31
    for a, b in zip(first, second):
        for key in a:
            np.testing.assert_array_equal(a[key], b[key])


def test_a_policy_trained_at_another_region_size_does_not_warn(tmp_path, small_maze):
    path = save_drl_policy(fresh_policy(8), tmp_path / "regions.pt", {"protocol": Protocol().to_dict()})
    planner = make_planner("drl", policy_file=str(path))
    with warnings.catch_warnings():
        warnings.simplefilter("error", ProtocolMismatchWarning)
        planner.reset(small_maze, Protocol(region_size=8.0), 0)
