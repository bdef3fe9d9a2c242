"""Training data and training loop of the block model (`pipeline.models.modeling_block_model`).

Data: `greedy_utility` with the sliver gate (the planner the sampled lookahead rolls out)
explores training mazes; every few steps the belief's block shares are a sample and the
ground truth's blocks its target. The loss is a binary cross-entropy on the blocks that are
mostly unknown: the known ones need no model. A share of the samples (`reveal_share`) get a
random part of their unknown blocks shown with their truth, as the model sees them when a
sampler feeds its own draws back. A plain loop, not Lightning: four epochs of a 170 k
parameter CNN take minutes and need neither checkpoints nor devices.
"""

from __future__ import annotations

import time
from collections import defaultdict
from dataclasses import dataclass

import cv2
import numpy as np
import torch
from torch import nn
from tqdm import tqdm

from pipeline.models.configuration_block_model import BlockModelConfig
from pipeline.models.modeling_block_model import BlockModel
from pipeline.planners import make_planner
from pipeline.prediction.block_maps import block_index, block_shares, true_blocks
from pipeline.training.checkpoints import TrainingCheckpoint
from pipeline.world.maps import GroundTruthMap
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import run_episode

UNKNOWN_BLOCK = 0.5  # a block is a training target when more than this share of it is unknown
NEAR_REACH = 4  # blocks: the error is measured within 20 m of the known free space, where the lookahead draws


@dataclass
class BlockSamples:
    """Per map, its snapshots' shares (n, 3, r, c) and its true blocks (r, c): maps differ in size."""

    shares: list[np.ndarray]
    truth: list[np.ndarray]

    def __len__(self) -> int:
        """The number of snapshots."""
        return sum(len(shares) for shares in self.shares)


def block_snapshots(
    ground_truth: GroundTruthMap, protocol: Protocol, block_m: float, every: int, seed: int = 0
) -> tuple[np.ndarray, np.ndarray]:
    """(shares (n, 3, r, c), truth (r, c)) of a gated `greedy_utility` episode, every `every` steps."""
    if every < 1:
        raise ValueError(f"every must be >= 1, got {every}")
    blocks, grid = block_index(ground_truth.shape, ground_truth.cell_size, block_m)
    shares: list[np.ndarray] = []

    def record(episode) -> None:
        if episode.steps % every == 0 and not episode.complete:
            shares.append(block_shares(episode.belief.grid, blocks, grid))

    run_episode(ground_truth, make_planner("greedy_utility", sliver_gate=True), protocol, seed, on_step=record)
    truth = true_blocks(ground_truth.free, blocks, grid)
    if not shares:  # an episode done in fewer than `every` steps (one scan saw a small maze): no sample
        return np.zeros((0, 3, *truth.shape), dtype=np.float32), truth
    return np.stack(shares), truth


def _reveal(
    shares: np.ndarray, truth: np.ndarray, reveal_share: float, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """(inputs, loss mask): for a `reveal_share` of samples, a random part (up to 90 %) of their
    unknown blocks set to their truth and dropped from the loss."""
    unknown = shares[:, 2] > UNKNOWN_BLOCK
    part = np.where(rng.random(len(shares)) < reveal_share, rng.random(len(shares)) * 0.9, 0.0)
    show = unknown & (rng.random(unknown.shape) < part[:, None, None])
    inputs = shares.copy()
    target = truth.astype(np.float32)
    for channel, value in enumerate((target, 1.0 - target, np.zeros_like(target))):
        inputs[:, channel][show] = value[show]
    return inputs, unknown & ~show


def near_unknown(shares: np.ndarray, reach: int) -> np.ndarray:
    """(n, r, c) bool: the mostly unknown blocks within `reach` blocks (king moves) of a block
    with known free cells: the blocks a lookahead `reach` x 5 m deep draws and rolls out on."""
    kernel = np.ones((2 * reach + 1, 2 * reach + 1), dtype=np.uint8)
    seen_free = [cv2.dilate((snapshot[0] > 0).astype(np.uint8), kernel) > 0 for snapshot in shares]
    return np.stack(seen_free) & (shares[:, 2] > UNKNOWN_BLOCK)


def block_error(model: BlockModel, samples: BlockSamples, reach: int = NEAR_REACH) -> tuple[float, float]:
    """(share of the unknown blocks near the known free space whose P(free) >= 0.5 disagrees with
    the truth, the same share for a constant "wall" guess)."""
    wrong = truly_free = total = 0
    for shares, truth in zip(samples.shares, samples.truth):
        probability = model.free_probability(shares)
        near = near_unknown(shares, reach)
        wrong += int(((probability >= 0.5) != truth[None])[near].sum())
        truly_free += int(np.broadcast_to(truth, near.shape)[near].sum())
        total += int(near.sum())
    return wrong / max(total, 1), truly_free / max(total, 1)


def _batches(samples: BlockSamples, batch_size: int, rng: np.random.Generator) -> list[list[tuple[int, int]]]:
    """Batches of (map index, snapshot index); a batch holds one map's grid size (maps differ in size)."""
    by_shape: dict[tuple[int, int], list[tuple[int, int]]] = defaultdict(list)
    for index, shares in enumerate(samples.shares):
        by_shape[shares.shape[-2:]] += [(index, i) for i in range(len(shares))]
    batches = []
    for items in by_shape.values():
        order = rng.permutation(len(items))
        for start in range(0, len(order), batch_size):
            batches.append([items[i] for i in order[start : start + batch_size]])
    return [batches[i] for i in rng.permutation(len(batches))]


def train_block_model(
    train: BlockSamples,
    held_out: BlockSamples | None,
    config: BlockModelConfig,
    epochs: int,
    batch_size: int = 128,
    lr: float = 3e-3,
    reveal_share: float = 0.7,
    seed: int = 0,
    log=None,
    checkpoint: TrainingCheckpoint | None = None,
) -> tuple[BlockModel, list[dict[str, float]]]:
    """A model fitted with AdamW and a one-cycle schedule; per epoch {epoch, loss, held_out_error
    (`block_error` within 20 m of the known free space), seconds}.

    With `checkpoint`, the whole state is saved after every epoch and a run killed part-way
    continues from its last finished epoch, the same model as an uninterrupted run's.
    """
    if not len(train):
        raise ValueError("no training snapshots: the block model needs at least one episode")
    torch.manual_seed(seed)
    rng = np.random.default_rng(seed)
    model = BlockModel(config)
    optimizer = torch.optim.AdamW(model.parameters(), lr=lr, weight_decay=1e-4)
    steps = epochs * len(_batches(train, batch_size, np.random.default_rng(seed)))
    schedule = torch.optim.lr_scheduler.OneCycleLR(optimizer, max_lr=lr, total_steps=max(steps, 1))
    history: list[dict[str, float]] = []
    first_epoch = 0
    state = checkpoint.load() if checkpoint is not None else None
    if state is not None:
        model.load_state_dict(state["model"])
        optimizer.load_state_dict(state["optimizer"])
        schedule.load_state_dict(state["schedule"])
        torch.set_rng_state(state["torch_rng"])
        rng.bit_generator.state = state["numpy_rng"]
        history, first_epoch = list(state["history"]), int(state["epoch"])
    for epoch in range(first_epoch, epochs):
        started, losses = time.perf_counter(), []
        model.train()
        for batch in tqdm(
            _batches(train, batch_size, rng), desc=f"block model epoch {epoch + 1}/{epochs}", unit="batch", leave=False
        ):
            shares = np.stack([train.shares[m][i] for m, i in batch])
            truth = np.stack([train.truth[m] for m, _ in batch])
            inputs, mask = _reveal(shares, truth, reveal_share, rng)
            if not mask.any():
                continue
            logits = model(torch.from_numpy(inputs))
            weight = torch.from_numpy(mask.astype(np.float32))
            loss = (
                nn.functional.binary_cross_entropy_with_logits(
                    logits, torch.from_numpy(truth.astype(np.float32)), reduction="none"
                )
                * weight
            ).sum() / weight.sum()
            optimizer.zero_grad()
            loss.backward()
            optimizer.step()
            schedule.step()
            losses.append(float(loss.detach()))
        model.eval()
        row = {
            "epoch": epoch + 1,
            "loss": float(np.mean(losses)) if losses else float("nan"),
            "held_out_error": block_error(model, held_out)[0]
            if held_out is not None and len(held_out)
            else float("nan"),
            "seconds": time.perf_counter() - started,
        }
        history.append(row)
        if log is not None:
            log(row)
        if checkpoint is not None:
            checkpoint.save(
                {
                    "epoch": epoch + 1,
                    "model": model.state_dict(),
                    "optimizer": optimizer.state_dict(),
                    "schedule": schedule.state_dict(),
                    "torch_rng": torch.get_rng_state(),
                    "numpy_rng": rng.bit_generator.state,
                    "history": history,
                }
            )
    return model.eval(), history
