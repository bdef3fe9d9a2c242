"""DAgger's shards: labelled episodes in the expert shards' format, deterministic, the policy driving."""

import numpy as np
from import_graph import ROOT

from pipeline.data.dagger import DaggerConfig, collect_dagger_shard, step_labels
from pipeline.data.expert_episodes import load_expert_episodes
from pipeline.data.observations import episode_observations
from pipeline.data.shards import ShardJob, read_shard, run_shards, shard_path
from pipeline.data.teacher_labels import TeacherLabelledDriver
from pipeline.planners import make_planner
from pipeline.world.maps import list_maps
from pipeline.world.protocol import Protocol

SHIPPED_POLICY = ROOT / "pipeline" / "assets" / "planner_guide.pt"


def config(maze_dir, **overrides):
    values = dict(
        maps=tuple(str(p) for p in list_maps(maze_dir)),
        episodes_per_shard=1,
        teacher="tare",
        teacher_options={},
        horizon=8,
        seed=4,
        protocol=Protocol(max_steps=30),
    )
    values.update(overrides)
    return DaggerConfig(**values)


def test_teacher_driven_shards_are_deterministic_and_replay_into_observations(generated_maze_dir, tmp_path):
    params = {"config": config(generated_maze_dir)}
    manifest = run_shards(collect_dagger_shard, 2, tmp_path / "a", params, progress=False)
    run_shards(collect_dagger_shard, 2, tmp_path / "b", params, workers=2, progress=False)
    for k in range(2):
        assert shard_path(tmp_path / "a", k).read_bytes() == shard_path(tmp_path / "b", k).read_bytes()
    totals = manifest["totals"]
    assert totals["episodes"] == 2 and 0 < totals["agreements"] <= totals["moves"] == totals["steps"] - 2
    episode = load_expert_episodes(shard_path(tmp_path / "a", 0))[0]
    arrays = episode_observations(episode, Protocol(max_steps=30), None, variants=("guide",))
    assert set(arrays) == {"guide"}
    actions = arrays["guide"]["actions"]
    assert actions.shape == (len(episode.positions), 8, 2) and np.abs(actions).max() <= 2
    assert np.abs(actions[:-1, 0]).sum(axis=1).min() > 0  # every state the robot moved from has a first step


def test_the_policy_drives_and_the_teacher_labels_what_it_reaches(generated_maze_dir, tmp_path):
    teacher_made = config(generated_maze_dir)
    policy_made = config(generated_maze_dir, student=str(SHIPPED_POLICY), round=1)
    for name, cfg in (("teacher", teacher_made), ("policy", policy_made)):
        (tmp_path / name).mkdir()
        collect_dagger_shard(ShardJob(0, str(tmp_path / name), "", {"config": cfg}))
    teacher, policy = (read_shard(shard_path(tmp_path / name, 0)) for name in ("teacher", "policy"))
    assert not np.array_equal(teacher["positions"], policy["positions"])  # another driver, another route
    assert policy["driver_agrees"].shape == (int(policy["summary_steps"]),)
    assert int(policy["summary_agreements"]) < int(policy["summary_moves"])  # the policy is not the teacher


def test_step_labels_pad_the_state_the_teacher_was_not_asked_about():
    planner = TeacherLabelledDriver(make_planner("tare"), horizon=2)
    planner.labels = [np.array([[4.0, 0.0], [8.0, 0.0]], np.float32)]
    planner.agrees = [True]
    trajectory = np.array([[0.0, 0.0], [4.0, 0.0]], np.float32)
    labels, agrees = step_labels(planner, trajectory)
    np.testing.assert_array_equal(labels[1], [[4.0, 0.0], [4.0, 0.0]])  # the final state: stay
    assert agrees.tolist() == [True, False]
