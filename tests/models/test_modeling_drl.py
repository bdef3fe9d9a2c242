"""The drl policy (pipeline/models/modeling_drl.py): its window slots are the robot's lattice
neighbours, slots without a node are masked, the greedy action respects the action mask, the
guidepost term is exactly weight x feature, exports round-trip, and the config refuses bad values."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pipeline.envs.explore_env import ExploreEnv
from pipeline.models.configuration_drl import DRLPolicyConfig
from pipeline.models.modeling_drl import (
    DRL_FORMAT,
    GUIDEPOST,
    MASKED_LOGIT,
    SLOTS,
    DRLPolicy,
    load_drl_policy,
    save_drl_policy,
)
from pipeline.prediction.observed_graph import STAY_SLOT, window_moves
from pipeline.world.mazes import MazeConfig, generate_maze, write_maze_png

TINY = {"max_nodes": 32, "d_model": 16, "heads": 2, "encoder_layers": 1}


def tiny_policy(seed: int = 0, **values) -> DRLPolicy:
    torch.manual_seed(seed)
    return DRLPolicy(DRLPolicyConfig(**{**TINY, **values})).eval()


def batch(observations: list[dict]) -> tuple[torch.Tensor, ...]:
    """The model's inputs for a list of unbatched environment observations."""
    return (
        torch.as_tensor(np.stack([o["features"] for o in observations])),
        torch.as_tensor(np.stack([o["node_mask"] for o in observations])).bool(),
        torch.as_tensor(np.stack([o["neighbors"] for o in observations])).long(),
        torch.as_tensor([int(o["robot"]) for o in observations]),
    )


def expected_slot_rows(env: ExploreEnv) -> np.ndarray:
    """Per window slot, the row of the lattice node there when a known-free edge leads to it and
    the node is among the observation's rows; the robot's row at the centre; else -1."""
    unwrapped = env.unwrapped
    view = unwrapped._view
    moves = window_moves(unwrapped.lattice, unwrapped._table, view.robot_node)
    row_of = {int(node): row for row, node in enumerate(unwrapped.row_nodes)}
    rows = np.full(SLOTS, -1, dtype=np.int64)
    for slot in np.flatnonzero(moves):
        rows[slot] = row_of.get(int(unwrapped._table.neighbour[view.robot_node, slot]), -1)
    rows[STAY_SLOT] = view.robot_row
    return rows


@pytest.fixture(scope="module")
def walks(small_maze_path, tmp_path_factory) -> list[list[tuple[dict, np.ndarray]]]:
    """(observation, expected slot rows) along two short random walks: the small maze, and a
    generated maze with fewer rows than the robot's window holds (some neighbours are not among
    the rows)."""
    maze = tmp_path_factory.mktemp("drl-maze") / "maze.png"
    write_maze_png(generate_maze(MazeConfig(side_m=(50.0, 50.0)), np.random.default_rng([7, 1])), maze)
    result = []
    for path, max_nodes in ((small_maze_path, 32), (maze, 6)):
        steps = []
        env = ExploreEnv(map=str(path), max_nodes=max_nodes, max_steps=40)
        obs, _ = env.reset(seed=0)
        rng = np.random.default_rng(1)
        for _ in range(12):
            steps.append((obs, expected_slot_rows(env)))
            obs, _, terminated, truncated, _ = env.step(int(rng.choice(np.flatnonzero(obs["action_mask"]))))
            if terminated or truncated:
                break
        env.close()
        result.append(steps)
    return result


@pytest.fixture(scope="module")
def walk(walks) -> list[tuple[dict, np.ndarray]]:
    """The small maze's walk (its observations stack into one batch)."""
    return walks[0]


def test_slot_rows_are_the_robots_lattice_neighbours(walks):
    policy = tiny_policy()
    for walk in walks:
        rows = policy.slot_rows(*batch([obs for obs, _ in walk])).numpy()  # one batch: each its own robot
        assert rows.shape == (len(walk), SLOTS)
        for (obs, expected), got in zip(walk, rows):
            np.testing.assert_array_equal(got, expected)
            # A slot has a node only where the environment allows the move (or at the centre).
            assert set(np.flatnonzero(got >= 0)) - {STAY_SLOT} <= set(np.flatnonzero(obs["action_mask"]))
        assert ((rows >= 0).sum(axis=1) - 1).max() >= 4  # the walk saw well-connected nodes
    # With 6 rows, some allowed moves lead to nodes beyond the rows: those slots have none.
    assert any((rows < 0)[obs["action_mask"].astype(bool)].any() for obs, rows in walks[1])
    assert all(
        np.array_equal(rows >= 0, obs["action_mask"].astype(bool) | (np.arange(SLOTS) == STAY_SLOT))
        for obs, rows in walks[0]
    )  # with 32 rows, every allowed move has its node


def test_slots_without_a_node_get_the_masked_logit(walk):
    policy = tiny_policy()
    observations = [obs for obs, _ in walk]
    with torch.no_grad():
        logits, value = policy(*batch(observations))
    assert logits.shape == (len(walk), SLOTS) and value.shape == (len(walk),)
    expected = np.stack([rows for _, rows in walk])
    assert np.all(logits.numpy()[expected < 0] == MASKED_LOGIT)
    present = logits.numpy()[expected >= 0]
    assert np.all(np.abs(present) <= policy.config.logit_clip + policy.config.guidepost_prior + 1e-4)
    # One observation alone gives what it gave in the batch.
    with torch.no_grad():
        alone, alone_value = policy(*batch(observations[3:4]))
    torch.testing.assert_close(alone[0], logits[3], rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(alone_value[0], value[3], rtol=1e-5, atol=1e-5)


def test_forward_refuses_the_wrong_feature_width(walk):
    features, node_mask, neighbors, robot = batch([walk[0][0]])
    with pytest.raises(ValueError, match="features must have 7 channels"):
        tiny_policy()(features[..., :5], node_mask, neighbors, robot)


def test_predict_action_is_the_best_allowed_slot(walk):
    policy = tiny_policy(seed=3)
    rng = np.random.default_rng(0)
    for obs, _ in walk:
        with torch.no_grad():
            logits = policy(*batch([obs]))[0][0].numpy()
        action = policy.predict_action(obs)  # the observation's own mask
        allowed = obs["action_mask"].astype(bool)
        assert allowed[action] and logits[action] == logits[allowed].max()
        for _ in range(8):
            mask = rng.random(SLOTS) < 0.3
            mask[rng.integers(SLOTS)] = True
            action = policy.predict_action(obs, mask)
            assert mask[action] and logits[action] == logits[mask].max()
        # A mask that allows only slots with no node still gets an allowed slot.
        nodeless = logits == MASKED_LOGIT
        if nodeless.any():
            assert nodeless[policy.predict_action(obs, nodeless)]


@pytest.mark.parametrize(
    "mask", [np.zeros(SLOTS, dtype=bool), np.ones(SLOTS - 1, dtype=bool), np.ones((5, 5), dtype=bool)]
)
def test_predict_action_refuses_an_empty_or_misshapen_mask(walk, mask):
    with pytest.raises(ValueError, match="action_mask must be 25 flags with at least one set"):
        tiny_policy().predict_action(walk[0][0], mask)


def test_the_guidepost_term_is_its_weight_times_the_feature(walk):
    with_prior = tiny_policy(seed=5, guidepost_prior=3.0)
    without = tiny_policy(seed=6, guidepost_prior=0.0)
    assert with_prior.guidepost_weight.item() == 3.0 and without.guidepost_weight.item() == 0.0
    assert isinstance(with_prior.guidepost_weight, torch.nn.Parameter)  # learned
    weights = {k: v for k, v in with_prior.state_dict().items() if k != "guidepost_weight"}
    assert without.load_state_dict(weights, strict=False).missing_keys == ["guidepost_weight"]
    observations = [obs for obs, _ in walk]
    inputs = batch(observations)
    with torch.no_grad():
        logits3, value3 = with_prior(*inputs)
        logits0, value0 = without(*inputs)
    rows = with_prior.slot_rows(*inputs)
    present = rows >= 0
    guidepost = torch.gather(inputs[0][..., GUIDEPOST], 1, rows.clamp(min=0))
    assert guidepost[present].sum() > 0  # some window slots lie on the guidepost
    torch.testing.assert_close((logits3 - logits0)[present], 3.0 * guidepost[present], rtol=0, atol=1e-5)
    assert torch.all(logits3[~present] == MASKED_LOGIT) and torch.all(logits0[~present] == MASKED_LOGIT)
    torch.testing.assert_close(value3, value0)  # the critic does not read the pointer's guidepost term


def test_save_and_load_round_trip(tmp_path, walk):
    policy = tiny_policy(seed=2, guidepost_prior=1.5, logit_clip=4.0)
    with torch.no_grad():
        policy.guidepost_weight.fill_(2.25)  # a trained weight, not the prior
    trained_on = {"protocol": {"node_resolution": 4.0}, "timesteps": 64, "env": {"maze_sides_m": [50.0]}}
    path = save_drl_policy(policy, tmp_path / "drl" / "policy.pt", trained_on)
    loaded, loaded_trained_on = load_drl_policy(path)
    assert loaded.config == policy.config and not loaded.training
    assert loaded_trained_on == trained_on
    assert loaded.guidepost_weight.item() == 2.25
    inputs = batch([obs for obs, _ in walk])
    with torch.no_grad():
        for a, b in zip(policy(*inputs), loaded(*inputs)):
            assert torch.equal(a, b)
    assert torch.load(path, weights_only=True)["format"] == DRL_FORMAT
    # No trained_on: an empty record.
    assert load_drl_policy(save_drl_policy(policy, tmp_path / "bare.pt"))[1] == {}


def test_loading_something_else_fails_in_one_line(tmp_path):
    torch.save({"format": "x", "config": {}}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match=r"other.pt: not a drl policy export \(format 'x'"):
        load_drl_policy(tmp_path / "other.pt")
    torch.save({"config": TINY, "state_dict": {}}, tmp_path / "unmarked.pt")
    with pytest.raises(ValueError, match=r"not a drl policy export \(format None"):
        load_drl_policy(tmp_path / "unmarked.pt")
    (tmp_path / "notes.txt").write_text("not a model\n")
    with pytest.raises(ValueError, match=r"notes.txt: not a drl policy export") as error:
        load_drl_policy(tmp_path / "notes.txt")
    assert "\n" not in str(error.value)
    torch.save([1, 2], tmp_path / "list.pt")
    with pytest.raises(ValueError, match="not a drl policy export"):
        load_drl_policy(tmp_path / "list.pt")
    with pytest.raises(FileNotFoundError, match="missing.pt"):
        load_drl_policy(tmp_path / "missing.pt")


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"d_model": 16, "heads": 3}, "model: heads (3) must divide d_model (16)"),
        ({"guidepost_prior": -1.0}, "model.guidepost_prior: must be a finite number >= 0, got -1.0"),
        ({"guidepost_prior": float("nan")}, "model.guidepost_prior: must be a finite number >= 0, got nan"),
        ({"guidepost_prior": float("inf")}, "model.guidepost_prior: must be a finite number >= 0, got inf"),
        ({"max_nodes": 0}, "model.max_nodes: must be a whole number >= 1, got 0"),
        ({"encoder_layers": 1.5}, "model.encoder_layers: must be a whole number >= 1, got 1.5"),
        ({"d_model": True}, "model.d_model: must be a whole number >= 1, got True"),
        ({"logit_clip": 0}, "model.logit_clip: must be a finite number > 0, got 0"),
        ({"window_scale": "10"}, "model.window_scale: must be a finite number > 0, got '10'"),
        (
            {"layers": 2},
            "model.layers: unknown setting (known: feature_dim, max_nodes, max_neighbors, d_model, heads, "
            "encoder_layers, window_scale, logit_clip, guidepost_prior), got 2",
        ),
    ],
)
def test_config_refuses_bad_values(values, message):
    """One line naming the key and what it must be."""
    with pytest.raises(ValueError) as refused:
        DRLPolicyConfig.from_dict(values)
    assert str(refused.value) == message


def test_config_round_trips_through_its_dict():
    config = DRLPolicyConfig(**TINY, guidepost_prior=0)
    assert DRLPolicyConfig.from_dict(config.to_dict()) == config
    assert config.guidepost_prior == 0.0 and isinstance(config.to_dict()["guidepost_prior"], float)
    assert DRLPolicyConfig.from_dict(None) == DRLPolicyConfig()
