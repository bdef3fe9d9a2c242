import numpy as np
import pytest

from pipeline.data.expert_episodes import load_expert_episodes
from pipeline.data.observations import (
    ObservationConfig,
    PlannerDataset,
    concatenate,
    crop_observations,
    episode_observations,
    history_index,
    load_observations,
    save_observations,
)
from pipeline.data.shards import shard_path
from pipeline.prediction.graph_observation import expert_action_deltas, rotate_steps
from pipeline.prediction.node_predictor import NodePredictor
from pipeline.world.protocol import Protocol


@pytest.fixture(scope="module")
def observations(expert_shard_dir):
    episodes = [e for k in range(2) for e in load_expert_episodes(shard_path(expert_shard_dir, k))]
    predictor = NodePredictor(lambda image: (image != 0).astype(np.float32))  # everything not known occupied is free
    parts = [
        episode_observations(e, Protocol(), predictor, ObservationConfig(max_nodes=96), episode_id=i)
        for i, e in enumerate(episodes)
    ]
    return episodes, {v: concatenate(p[v] for p in parts) for v in ("guide", "dare")}


def test_observations_follow_the_expert(observations):
    episodes, obs = observations
    guide, dare = obs["guide"], obs["dare"]
    steps = sum(len(e.positions) for e in episodes)
    assert len(guide["actions"]) == len(dare["actions"]) == steps
    assert guide["features"].shape == (steps, 96, 7) and guide["neighbors"].shape == (steps, 96, 25)
    # Replaying the actions from each position lands on the expert's next waypoint.
    for e_id, episode in enumerate(episodes):
        rows = np.nonzero(guide["episode"] == e_id)[0]
        for row, position, nxt in zip(rows[:-1], episode.positions[:-1], episode.positions[1:]):
            np.testing.assert_allclose(position + guide["actions"][row, 0] * 4.0, nxt, atol=1e-3)
    # The robot's row is itself at distance 0; neighbours point at valid rows only.
    robot = guide["features"][np.arange(steps), guide["robot"]]
    assert np.abs(robot[:, :2].astype(np.float32)).max() < 1e-6
    nb = guide["neighbors"]
    valid = nb >= 0
    rows = np.broadcast_to(np.arange(steps)[:, None, None], nb.shape)
    assert guide["node_mask"][rows[valid], nb[valid]].all()
    # Only the guide variant has predicted nodes; DARE's graph is the observed one.
    assert guide["features"][..., 5].max() == 1 and dare["features"][..., 5].max() == 0


def test_history_never_crosses_episodes():
    episode = np.array([0, 0, 0, 1, 1])
    step = np.array([0, 1, 2, 0, 1])
    np.testing.assert_array_equal(history_index(episode, step, 2), [[0, 0], [0, 1], [1, 2], [3, 3], [3, 4]])


def test_expert_deltas_pad_with_stays_and_reject_long_jumps():
    future = np.array([[4.0, 0.0], [8.0, 4.0], [8.0, 4.0]])
    np.testing.assert_array_equal(expert_action_deltas((0.0, 0.0), future, 4.0), [[1, 0], [1, 1], [0, 0]])
    with pytest.raises(ValueError, match="window"):
        expert_action_deltas((0.0, 0.0), np.array([[12.0, 0.0]]), 4.0)


def test_rotations_form_the_dihedral_group():
    v = np.array([[1, 2]])
    assert rotate_steps(v, 1, False).tolist() == [[-2, 1]]
    assert rotate_steps(v, 4, False).tolist() == v.tolist()
    assert rotate_steps(rotate_steps(v, 0, True), 0, True).tolist() == v.tolist()


def test_dataset_augments_positions_and_actions_together(observations, tmp_path):
    _, obs = observations
    save_observations(tmp_path / "o.npz", obs["guide"], {"variant": "guide"})
    arrays, meta = load_observations(tmp_path / "o.npz")
    assert meta == {"variant": "guide"}
    plain = PlannerDataset(arrays, obs_steps=2)
    augmented = PlannerDataset(arrays, obs_steps=2, augment=True, seed=1)
    for i in range(0, len(plain), 7):
        a, b = plain[i], augmented[i]
        assert a["features"].shape[0] == 2
        # Rotations and flips keep lengths: |dx, dy| and |action| are unchanged.
        np.testing.assert_allclose(a["features"][..., :2].norm(dim=-1), b["features"][..., :2].norm(dim=-1), atol=1e-3)
        np.testing.assert_array_equal(
            a["actions"].abs().sum(-1).sort().values, b["actions"].abs().sum(-1).sort().values
        )
    with pytest.raises(FileNotFoundError, match="build_observations"):
        load_observations(tmp_path / "missing.npz")


def test_cropping_keeps_the_nearest_rows_and_drops_links_to_the_rest(observations):
    _, obs = observations
    cropped = crop_observations(obs["guide"], 40)
    assert cropped["features"].shape[1] == 40 and cropped["neighbors"].max() < 40
    np.testing.assert_array_equal(cropped["features"], obs["guide"]["features"][:, :40])
    kept = obs["guide"]["neighbors"][:, :40]
    np.testing.assert_array_equal(cropped["neighbors"][kept < 40], kept[kept < 40])
    with pytest.raises(ValueError, match="cannot crop"):
        crop_observations(obs["guide"], 200)
