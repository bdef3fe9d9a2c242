"""The diffusion policy: action coding, graph attention masking, shapes, config, training and sampling."""

from __future__ import annotations

import dataclasses
import itertools
import json

import numpy as np
import pytest
import torch

from pipeline.models import (
    DiffusionPolicy,
    DiffusionPolicyConfig,
    GraphEncoder,
    build_attention_mask,
    decode_actions,
    encode_actions,
)

ROWS, COLS = 3, 4  # a 3 x 4 lattice: N = 12 nodes
N_NODES = ROWS * COLS
N_NEIGHBORS = 8
INVALID = (10, 11)  # padded nodes of the test graph
TINY = DiffusionPolicyConfig(
    feature_dim=5,
    max_nodes=N_NODES,
    max_neighbors=N_NEIGHBORS,
    d_model=32,
    heads=4,
    encoder_layers=1,
    denoiser_layers=2,
    num_inference_steps=10,
)


pytestmark = pytest.mark.usefixtures("one_torch_thread")


def lattice_graph() -> tuple[torch.Tensor, torch.Tensor]:
    """(neighbors (N, M) with -1 padding, node_mask (N,)): 8-connected lattice, the last two nodes padded.

    Node 9's list also names padded node 10, as a stale neighbour list might: the mask must block it.
    """
    node_mask = torch.ones(N_NODES, dtype=torch.bool)
    node_mask[list(INVALID)] = False
    neighbors = torch.full((N_NODES, N_NEIGHBORS), -1, dtype=torch.long)
    for node in range(N_NODES):
        if not node_mask[node]:
            continue
        r, c = divmod(node, COLS)
        found = [
            (r + dr) * COLS + (c + dc)
            for dr, dc in itertools.product((-1, 0, 1), repeat=2)
            if (dr, dc) != (0, 0) and 0 <= r + dr < ROWS and 0 <= c + dc < COLS
        ]
        found = [j for j in found if node_mask[j] or node == 9]
        neighbors[node, : len(found)] = torch.tensor(found)
    return neighbors, node_mask


def observation(config: DiffusionPolicyConfig, batch: int = 1, seed: int = 0) -> dict[str, torch.Tensor]:
    """A batch of T_o observations of the lattice graph with random features; the robot at node 5."""
    generator = torch.Generator().manual_seed(seed)
    neighbors, node_mask = lattice_graph()
    steps = config.obs_steps
    return {
        "features": torch.randn(batch, steps, N_NODES, config.feature_dim, generator=generator),
        "node_mask": node_mask.expand(batch, steps, N_NODES).clone(),
        "neighbors": neighbors.expand(batch, steps, N_NODES, N_NEIGHBORS).clone(),
        "robot": torch.full((batch, steps), 5, dtype=torch.long),
    }


# ----------------------------------------------------------------------------- actions
def test_action_round_trip_all_25_deltas():
    config = DiffusionPolicyConfig()
    deltas = torch.tensor(list(itertools.product(config.step_values, repeat=2))).view(25, 1, 2)
    encoded = encode_actions(deltas, config)
    assert encoded.shape == (25, 1, config.action_dim)
    assert set(encoded.unique().tolist()) == {-1.0, 1.0}
    assert (encoded.view(25, 1, 2, 5) == 1).sum(-1).eq(1).all()  # exactly one hot bin per axis
    decoded, expected = decode_actions(encoded, config)
    assert decoded.dtype == torch.long
    assert torch.equal(decoded, deltas)
    assert torch.equal(expected, deltas.float())


def test_encode_rejects_delta_outside_step_values():
    deltas = torch.zeros(2, 8, 2, dtype=torch.long)
    deltas[1, 3, 0] = 3
    with pytest.raises(ValueError, match=r"\[3\]"):
        encode_actions(deltas, DiffusionPolicyConfig())


def test_decode_expected_is_the_weighted_mean_of_active_bins():
    config = DiffusionPolicyConfig()
    x = -torch.ones(1, 1, config.action_dim)
    x[0, 0, 3] = x[0, 0, 4] = 1.0  # axis 0: bins +1 and +2 equally on -> 1.5
    x[0, 0, 5] = 0.0  # axis 1: bin -2 half on, bin -1 fully on -> (-2 * 0.5 - 1) / 1.5
    x[0, 0, 6] = 1.0
    deltas, expected = decode_actions(x, config)
    assert deltas[0, 0, 1].item() == -1
    assert expected[0, 0, 0].item() == pytest.approx(1.5)
    assert expected[0, 0, 1].item() == pytest.approx(-2.0 / 1.5)


# ----------------------------------------------------------------------------- graph encoder
def test_attention_mask_follows_edges_and_isolates_padding():
    neighbors, node_mask = lattice_graph()
    allowed = build_attention_mask(neighbors.unsqueeze(0), node_mask.unsqueeze(0))[0]
    assert allowed.shape == (N_NODES, N_NODES) and allowed.dtype == torch.bool
    assert allowed[5, 0] and allowed[5, 10 - COLS] and allowed[5, 5]  # diagonal neighbour, lattice neighbour, self
    assert not allowed[0, 3] and not allowed[0, 11]  # far nodes are blocked
    assert not allowed[9, 10]  # listed neighbour 10 is padded: blocked
    assert not allowed[:, 10].logical_and(node_mask).any()  # no valid node sees a padded one
    for padded in INVALID:
        row = torch.zeros(N_NODES, dtype=torch.bool)
        row[padded] = True
        assert torch.equal(allowed[padded], row)  # self only, never an all-masked row
    # Exactly the listed (valid) neighbours plus self, for every valid node.
    for node in range(N_NODES):
        if node_mask[node]:
            listed = {j for j in neighbors[node].tolist() if j >= 0 and node_mask[j]} | {node}
            assert set(allowed[node].nonzero().flatten().tolist()) == listed


def test_encoder_ignores_padded_nodes_but_not_valid_ones():
    torch.manual_seed(0)
    encoder = GraphEncoder(TINY).eval()
    obs = observation(TINY, batch=1)
    features, node_mask, neighbors = obs["features"][:, 0], obs["node_mask"][:, 0], obs["neighbors"][:, 0]
    robot = obs["robot"][:, 0]
    with torch.no_grad():
        z = encoder(features, node_mask, neighbors, robot)
        changed = features.clone()
        changed[:, list(INVALID)] = 100.0 * torch.randn(1, len(INVALID), TINY.feature_dim)
        assert torch.allclose(encoder(changed, node_mask, neighbors, robot), z, atol=1e-6)
        changed = features.clone()
        changed[:, 0] += 5.0  # a valid node, not a neighbour of the robot: reached by its cross-attention
        assert not torch.allclose(encoder(changed, node_mask, neighbors, robot), z, atol=1e-4)


# ----------------------------------------------------------------------------- policy
def test_shapes():
    torch.manual_seed(0)
    policy = DiffusionPolicy(TINY).eval()
    obs = observation(TINY, batch=3)
    z = policy.encode_observations(**obs)
    assert z.shape == (3, TINY.obs_steps, TINY.d_model)
    noise = policy.noise_net(torch.randn(3, TINY.horizon, TINY.action_dim), torch.tensor([0, 50, 99]), z)
    assert noise.shape == (3, TINY.horizon, TINY.action_dim)
    out = policy.predict_action(obs, num_inference_steps=3)
    assert out["deltas"].shape == (3, TINY.horizon, 2) and out["deltas"].dtype == torch.long
    assert out["expected"].shape == (3, TINY.horizon, 2) and out["expected"].dtype == torch.float32
    assert out["raw"].shape == (3, TINY.horizon, TINY.action_dim)
    assert out["raw"].abs().max() <= 1.0
    assert set(out["deltas"].unique().tolist()) <= set(TINY.step_values)
    assert policy.num_parameters() == sum(p.numel() for p in policy.parameters()) > 0


def test_wrong_observation_length_is_an_error():
    policy = DiffusionPolicy(TINY)
    obs = observation(dataclasses.replace(TINY, obs_steps=3))
    with pytest.raises(ValueError, match="T_o=2"):
        policy.predict_action(obs, num_inference_steps=2)


def test_loss_reaches_the_encoder():
    torch.manual_seed(0)
    policy = DiffusionPolicy(TINY)
    batch = observation(TINY, batch=2) | {"actions": torch.zeros(2, TINY.horizon, 2, dtype=torch.long)}
    loss = policy.compute_loss(batch)
    assert loss.ndim == 0 and torch.isfinite(loss)
    loss.backward()
    assert policy.encoder.embed.weight.grad.abs().sum() > 0


@pytest.mark.parametrize("sampler", ["ddpm", "ddim"])
def test_samplers_run_with_requested_steps(sampler):
    torch.manual_seed(0)
    policy = DiffusionPolicy(dataclasses.replace(TINY, sampler=sampler)).eval()
    expected_class = {"ddpm": "DDPMScheduler", "ddim": "DDIMScheduler"}[sampler]
    assert type(policy.inference_scheduler).__name__ == expected_class
    assert policy.inference_scheduler.config.num_train_timesteps == TINY.num_train_timesteps
    raw = policy.sample(observation(TINY, batch=2), num_inference_steps=4)
    assert raw.shape == (2, TINY.horizon, TINY.action_dim)
    assert len(policy.inference_scheduler.timesteps) == 4


@pytest.mark.parametrize("sampler", ["ddpm", "ddim"])
def test_sampling_is_deterministic_with_a_generator(sampler):
    torch.manual_seed(0)
    policy = DiffusionPolicy(dataclasses.replace(TINY, sampler=sampler)).eval()
    obs = observation(TINY, batch=2)
    first = policy.sample(obs, 5, generator=torch.Generator().manual_seed(7))
    again = policy.sample(obs, 5, generator=torch.Generator().manual_seed(7))
    other = policy.sample(obs, 5, generator=torch.Generator().manual_seed(8))
    assert torch.equal(first, again)
    assert not torch.equal(first, other)


@pytest.mark.parametrize("sampler", ["ddpm", "ddim"])
def test_sample_matches_a_plain_denoising_loop(sampler):
    """sample() precomputes all K steps' conditioning in one batch: it must equal calling the net step by step."""
    torch.manual_seed(0)
    policy = DiffusionPolicy(dataclasses.replace(TINY, sampler=sampler)).eval()
    obs = observation(TINY, batch=2)
    obs["features"][1] += 1.0  # two different observations, so a mixed-up batch order shows
    got = policy.sample(obs, 6, generator=torch.Generator().manual_seed(3))
    generator = torch.Generator().manual_seed(3)
    with torch.no_grad():
        z = policy.encode_observations(**obs)
        x = torch.randn(2, TINY.horizon, TINY.action_dim, generator=generator)
        scheduler = policy.inference_scheduler
        scheduler.set_timesteps(6)
        for t in scheduler.timesteps:
            x = scheduler.step(policy.noise_net(x, t.expand(2), z), t, x, generator=generator).prev_sample
    assert torch.allclose(got, x.clamp(-1, 1), atol=1e-5)


def test_traced_denoiser_samples_what_the_eager_net_samples():
    """trace_denoiser() only changes how the net runs: same samples, per batch size; train() drops the traces."""
    torch.manual_seed(0)
    policy = DiffusionPolicy(TINY).eval()
    samples = {}
    for batch in (1, 3):
        obs = observation(TINY, batch=batch)
        samples[batch] = policy.sample(obs, 6, generator=torch.Generator().manual_seed(4))
    policy.trace_denoiser()
    for batch in (1, 3, 1):  # a second shape gets its own trace; the first is reused
        got = policy.sample(observation(TINY, batch=batch), 6, generator=torch.Generator().manual_seed(4))
        assert torch.allclose(got, samples[batch], atol=1e-5)
    assert len(policy.traced_denoiser._traces) == 2
    with torch.no_grad():
        policy.noise_net.action_out.bias.add_(1.0)  # new weights (as training would make) ...
    policy.train()
    assert policy.traced_denoiser is None  # ... so the frozen traces are gone
    changed = policy.eval().sample(observation(TINY, batch=1), 6, generator=torch.Generator().manual_seed(4))
    assert not torch.allclose(changed, samples[1], atol=1e-3)


@pytest.fixture(scope="module")
def overfit():
    """A DDIM policy trained for 200 Adam steps on one observation/action pair repeated 32 times."""
    previous = torch.get_num_threads()
    torch.set_num_threads(1)  # module fixtures run before the per-test `one_thread`
    torch.manual_seed(0)
    config = dataclasses.replace(TINY, sampler="ddim")
    policy = DiffusionPolicy(config)
    generator = torch.Generator().manual_seed(1)
    target = torch.tensor(config.step_values)[torch.randint(0, 5, (1, config.horizon, 2), generator=generator)]
    one = observation(config, batch=1, seed=3)
    batch = {key: value.expand(32, *value.shape[1:]).clone() for key, value in one.items()}
    batch["actions"] = target.expand(32, -1, -1).clone()
    optimizer = torch.optim.Adam(policy.parameters(), lr=3e-3)
    losses = []
    for _ in range(200):
        loss = policy.compute_loss(batch)
        optimizer.zero_grad()
        loss.backward()
        optimizer.step()
        losses.append(loss.item())
    torch.set_num_threads(previous)
    return policy.eval(), one, target, losses


def test_loss_is_finite_and_drops_when_overfitting(overfit):
    _, _, _, losses = overfit
    assert all(torch.isfinite(torch.tensor(losses)))
    start, end = sum(losses[:10]) / 10, sum(losses[-10:]) / 10
    assert end < 0.5 * start, (start, end)


def test_overfit_policy_reproduces_its_action_sequence(overfit):
    policy, obs, target, _ = overfit
    out = policy.predict_action(obs, num_inference_steps=10, generator=torch.Generator().manual_seed(0))
    matches = (out["deltas"] == target).all(-1).float().mean().item()
    # A majority (6 of 8 steps), not all: one sampled step can still land on a neighbouring bin.
    assert matches >= 0.75, (out["deltas"].tolist(), target.tolist())


# ----------------------------------------------------------------------------- config
@pytest.mark.parametrize(
    "overrides, message",
    [
        (dict(d_model=30, heads=4), "divisible"),
        (dict(d_model=33, heads=1), "even"),
        (dict(sampler="euler"), "sampler"),
        (dict(horizon=4, action_steps=5), "horizon >= action_steps"),
        (dict(action_steps=0), "action_steps"),
        (dict(step_values=(0,)), "at least 2"),
        (dict(step_values=(-1, 0, 0)), "distinct"),
        (dict(step_values=(-1.5, 0, 1.5)), "step_values"),
        (dict(clip_sample=1), "clip_sample"),
        (dict(beta_schedule="cosine"), "beta_schedule"),
        (dict(prediction_type="noise"), "prediction_type"),
        (dict(num_inference_steps=200), "num_inference_steps"),
        (dict(dropout=1.0), "dropout"),
        (dict(encoder_layers=0), "encoder_layers"),
    ],
)
def test_config_validation(overrides, message):
    with pytest.raises(ValueError, match=message):
        DiffusionPolicyConfig(**overrides)


def test_config_round_trip_and_unknown_keys():
    config = DiffusionPolicyConfig(sampler="ddim", step_values=(-4, 0, 4), dropout=0.1)
    assert config.action_dim == 6
    values = json.loads(json.dumps(config.to_dict()))  # lists, as YAML or JSON give them back
    assert DiffusionPolicyConfig.from_dict(values) == config
    assert DiffusionPolicyConfig.from_dict(values).step_values == (-4, 0, 4)  # a tuple again: hashable
    assert hash(DiffusionPolicyConfig.from_dict(values)) == hash(config)
    with pytest.raises(ValueError, match=r"^model\.depth: unknown setting \(known: feature_dim, .*\), got 3$"):
        DiffusionPolicyConfig.from_dict(values | {"depth": 3, "colour": "red"})
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.d_model = 8  # type: ignore[misc]


@pytest.mark.parametrize(
    "values, message",
    [
        ({"heads": 0}, "model.heads: must be a whole number >= 1, got 0"),
        ({"max_nodes": 3.0}, "model.max_nodes: must be a whole number >= 1 (nodes per padded graph), got 3.0"),
        ({"d_model": True}, "model.d_model: must be a whole number >= 1, got True"),
        ({"dropout": 1.0}, "model.dropout: must be a number in [0, 1), got 1.0"),
        ({"window_scale": float("nan")}, "model.window_scale: must be a finite number > 0, got nan"),
        ({"sampler": "euler"}, "model.sampler: must be one of 'ddpm', 'ddim', got 'euler'"),
        ({"clip_sample": "yes"}, "model.clip_sample: must be true or false, got 'yes'"),
        (
            {"step_values": [0]},
            "model.step_values: must be a list of at least 2 items of a whole number (lattice steps), got [0]",
        ),
        ({"step_values": [-1, 0.5]}, "model.step_values[1]: must be a whole number (lattice steps), got 0.5"),
        ({"step_values": [1, 1]}, "model: step_values must be distinct, got [1, 1]"),
        ({"d_model": 30, "heads": 4}, "model: d_model (30) must be divisible by heads (4)"),
        ({"horizon": 1, "action_steps": 2}, "model: need horizon >= action_steps, got horizon=1, action_steps=2"),
        ({"num_inference_steps": 101}, "model: num_inference_steps (101) must not exceed num_train_timesteps (100)"),
    ],
)
def test_a_bad_value_from_a_mapping_is_one_line_naming_its_key(values, message):
    with pytest.raises(ValueError) as refused:
        DiffusionPolicyConfig.from_dict(values)
    assert str(refused.value) == message


def test_numpy_counts_are_counts_and_defaults_round_trip():
    config = DiffusionPolicyConfig.from_dict({"max_nodes": np.int64(96), "window_scale": 10})
    assert type(config.max_nodes) is int and type(config.window_scale) is float
    assert DiffusionPolicyConfig.from_dict(DiffusionPolicyConfig().to_dict()) == DiffusionPolicyConfig()
    assert DiffusionPolicyConfig().to_dict()["step_values"] == [-2, -1, 0, 1, 2]


def test_paper_config():
    paper = DiffusionPolicyConfig.paper()
    assert (paper.d_model, paper.heads, paper.encoder_layers, paper.denoiser_layers) == (256, 8, 6, 8)
    assert paper.horizon == DiffusionPolicyConfig().horizon
    assert DiffusionPolicyConfig.paper(sampler="ddim").sampler == "ddim"


def test_window_slots_place_neighbours_at_their_lattice_offsets():
    config = DiffusionPolicyConfig(max_nodes=4, d_model=32, heads=2, encoder_layers=1, denoiser_layers=1)
    encoder = GraphEncoder(config).eval()
    features = torch.zeros(1, 4, config.feature_dim)
    features[0, 1, 0] = 0.1  # one lattice step east of the robot (4 m / 40 m)
    features[0, 2, 1] = -0.2  # two steps south
    features[0, 3, 0] = 0.5  # far away: not in the window, though listed as a neighbour
    neighbors = torch.full((1, 4, 25), -1)
    neighbors[0, 0, :3] = torch.tensor([1, 2, 3])
    with torch.no_grad():
        h = torch.randn(1, 4, 32)
        slots = encoder.window_slots(h, features, torch.ones(1, 4, dtype=torch.bool), neighbors, torch.tensor([0]))
    slots = slots.view(25, config.slot_width)
    projected = encoder.slot_proj(h[0])
    with torch.no_grad():
        torch.testing.assert_close(slots[12], projected[0])  # the robot at the centre
        torch.testing.assert_close(slots[2 * 5 + 3], projected[1])  # (dx, dy) = (+1, 0)
        torch.testing.assert_close(slots[0 * 5 + 2], projected[2])  # (0, -2)
        empty = [k for k in range(25) if k not in (12, 13, 2)]
        torch.testing.assert_close(slots[empty], encoder.absent[empty])
