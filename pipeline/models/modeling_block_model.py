"""The block model: P(free) of every block of the map from the block shares seen so far.

A residual stack of dilated 3 x 3 convolutions over the block grid (`block_maps.block_shares`
plus the outer ring). Fully convolutional, so one model serves any maze size. Trained with a
binary cross-entropy on the unknown blocks only (`pipeline.training.block_model`).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any, cast

import numpy as np
import torch
from torch import nn

from pipeline.models.configuration_block_model import INPUT_CHANNELS, BlockModelConfig
from pipeline.models.exports import read_weights_file, write_weights_file
from pipeline.prediction.block_maps import block_shares, border_ring

BLOCK_MODEL_FORMAT = "guide-block-model/1"


class BlockModel(nn.Module):
    def __init__(self, config: BlockModelConfig):
        super().__init__()
        self.config = config
        width = config.width
        self.stem = nn.Conv2d(INPUT_CHANNELS, width, 3, padding=1)
        self.layers = nn.ModuleList(
            nn.Sequential(
                nn.GELU(), nn.Conv2d(width, width, 3, padding=d, dilation=d), nn.GroupNorm(config.groups, width)
            )
            for d in config.dilations
        )
        self.head = nn.Sequential(nn.GELU(), nn.Conv2d(width, 1, 1))

    def forward(self, shares: torch.Tensor) -> torch.Tensor:
        """(B, 3, rows, cols) block shares -> (B, rows, cols) logits of P(free)."""
        if shares.ndim != 4 or shares.shape[1] != INPUT_CHANNELS - 1:
            raise ValueError(f"expected block shares (B, {INPUT_CHANNELS - 1}, rows, cols), got {tuple(shares.shape)}")
        ring = torch.from_numpy(border_ring(cast(tuple[int, int], tuple(shares.shape[-2:])))).to(shares)
        hidden = self.stem(torch.cat([shares, ring.expand(len(shares), 1, *ring.shape)], 1))
        for layer in self.layers:
            hidden = hidden + layer(hidden)
        return self.head(hidden)[:, 0]

    @torch.no_grad()
    def free_probability(self, shares: np.ndarray, temperature: float = 1.0) -> np.ndarray:
        """(3, rows, cols) or (B, 3, rows, cols) shares -> P(free) of the same leading shape.
        `temperature` > 1 softens the probabilities (logits divided by it): a model trained
        long is overconfident, and maps drawn from it too alike."""
        if not temperature > 0:
            raise ValueError(f"temperature must be positive, got {temperature!r}")
        batch = np.asarray(shares, dtype=np.float32)
        single = batch.ndim == 3
        probability = torch.sigmoid(self(torch.from_numpy(batch[None] if single else batch)) / temperature).numpy()
        return probability[0] if single else probability


def belief_free_probability(
    model: BlockModel, belief: np.ndarray, blocks: np.ndarray, grid: tuple[int, int]
) -> np.ndarray:
    """P(free) of every block given a belief grid; known blocks get the model's guess too."""
    return model.free_probability(block_shares(belief, blocks, grid))


def save_block_model(model: BlockModel, path: str | Path, trained_on: dict[str, Any] | None = None) -> Path:
    payload = {
        "format": BLOCK_MODEL_FORMAT,
        "config": model.config.to_dict(),
        "state_dict": model.state_dict(),
        "trained_on": trained_on or {},
    }
    return write_weights_file(payload, path)


def block_model_protocol(path: str | Path) -> dict | None:
    """The protocol the block model in `path` was trained at (None: not recorded)."""
    payload = read_weights_file(path, "a block model file")
    return (payload.get("trained_on") or {}).get("protocol")


def load_block_model(path: str | Path) -> BlockModel:
    """The model in `path`, in eval mode; a one-line error if it is not a block model file."""
    payload = read_weights_file(path, "a block model file")
    if payload.get("format") != BLOCK_MODEL_FORMAT:
        raise ValueError(
            f"{path}: not a block model file (format {payload.get('format')!r}, expected {BLOCK_MODEL_FORMAT!r})"
        )
    model = BlockModel(BlockModelConfig.from_dict(payload["config"]))
    model.load_state_dict(payload["state_dict"])
    return model.eval()
