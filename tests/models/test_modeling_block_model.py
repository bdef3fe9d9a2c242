"""The block model: shapes on any grid, the ring channel, saving and loading, config checks."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from pipeline.models.configuration_block_model import BlockModelConfig
from pipeline.models.modeling_block_model import BlockModel, load_block_model, save_block_model


def test_predicts_a_probability_per_block_on_any_grid():
    model = BlockModel(BlockModelConfig(width=8, dilations=(1, 2), groups=4)).eval()
    shares = np.random.default_rng(0).dirichlet(np.ones(3), size=(2, 7, 9)).transpose(0, 3, 1, 2).astype(np.float32)
    probability = model.free_probability(shares)
    assert probability.shape == (2, 7, 9) and np.all((probability > 0) & (probability < 1))
    assert model.free_probability(shares[0]).shape == (7, 9)
    assert np.allclose(model.free_probability(shares[0]), probability[0], atol=1e-6)
    with pytest.raises(ValueError, match=r"expected block shares \(B, 3, rows, cols\)"):
        model(torch.zeros(1, 4, 5, 5))
    logits = model(torch.from_numpy(shares)).detach().numpy()
    softened = model.free_probability(shares, temperature=2.0)
    assert np.allclose(softened, 1 / (1 + np.exp(-logits / 2)), atol=1e-6)
    assert np.all(np.abs(softened - 0.5) < np.abs(probability - 0.5) + 1e-7)  # pulled toward 0.5
    with pytest.raises(ValueError, match="temperature must be positive"):
        model.free_probability(shares, temperature=0.0)


def test_save_and_load_round_trip(tmp_path):
    config = BlockModelConfig(width=8, dilations=(1, 2, 4), groups=2, block_m=4.0)
    model = BlockModel(config).eval()
    path = save_block_model(model, tmp_path / "block_model.pt", {"maps": ["a.png"]})
    loaded = load_block_model(path)
    assert loaded.config == config and not loaded.training
    shares = np.full((3, 6, 6), 1 / 3, dtype=np.float32)
    assert np.array_equal(loaded.free_probability(shares), model.free_probability(shares))
    torch.save({"format": "guide-inpainter/1", "config": {}}, tmp_path / "other.pt")
    with pytest.raises(ValueError, match="not a block model file"):
        load_block_model(tmp_path / "other.pt")
    with pytest.raises(FileNotFoundError, match="expected a block model file"):
        load_block_model(tmp_path / "missing.pt")


@pytest.mark.parametrize(
    ("values", "message"),
    [
        ({"width": 0}, "model.width: must be a whole number >= 1, got 0"),
        ({"width": 12, "groups": 5}, "model: groups (5) must divide width (12)"),
        ({"dilations": [1, 0]}, "model.dilations[1]: must be a whole number >= 1, got 0"),
        ({"dilations": []}, "model.dilations: must be a non-empty list of a whole number >= 1, got []"),
        ({"dilations": [1, 2.0]}, "model.dilations[1]: must be a whole number >= 1, got 2.0"),
        ({"block_m": -5.0}, "model.block_m: must be a finite number > 0 (metres), got -5.0"),
        ({"widht": 8}, "model.widht: unknown setting (known: width, dilations, groups, block_m), got 8"),
    ],
)
def test_config_refuses_bad_values(values, message):
    """One line naming the key and what it must be."""
    with pytest.raises(ValueError) as refused:
        BlockModelConfig.from_dict(values)
    assert str(refused.value) == message


def test_config_round_trips_through_its_dict():
    config = BlockModelConfig.from_dict({"width": 8, "dilations": [1, 2, 4], "groups": 2, "block_m": 4})
    assert config.dilations == (1, 2, 4) and config.block_m == 4.0  # a tuple and a float once made: hashable
    assert hash(config) == hash(BlockModelConfig.from_dict(config.to_dict()))
    assert config.to_dict() == {"width": 8, "dilations": [1, 2, 4], "groups": 2, "block_m": 4.0}
    assert BlockModelConfig.from_dict(config.to_dict()) == config
    assert BlockModelConfig.from_dict(None) == BlockModelConfig()
