"""Block model data and training on small mazes: snapshots, reveals, and a fit that learns."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from pipeline.models.configuration_block_model import BlockModelConfig
from pipeline.prediction.block_maps import block_index, true_blocks
from pipeline.training.block_model import (
    BlockSamples,
    _reveal,
    block_error,
    block_snapshots,
    near_unknown,
    train_block_model,
)
from pipeline.world.maps import list_maps, load_map
from pipeline.world.protocol import Protocol


def test_snapshots_follow_a_gated_greedy_episode(small_maze):
    shares, truth = block_snapshots(small_maze, Protocol(), 5.0, every=2)
    blocks, grid = block_index(small_maze.shape, small_maze.cell_size, 5.0)
    assert shares.shape[1:] == (3, *grid) and len(shares) >= 5
    assert np.array_equal(truth, true_blocks(small_maze.free, blocks, grid))
    unknown = shares[:, 2].sum(axis=(1, 2))
    assert np.all(np.diff(unknown) <= 1e-6) and unknown[0] > unknown[-1]  # the map is seen more and more


def test_an_episode_done_before_the_first_snapshot_gives_no_sample(small_maze):
    seen_at_once = replace(Protocol(), done_unknown_cells=small_maze.free_cell_count - 1)  # done after one move
    shares, truth = block_snapshots(small_maze, seen_at_once, 5.0, every=50)
    assert shares.shape == (0, 3, *truth.shape) and shares.dtype == np.float32


def test_reveal_shows_part_of_the_unknown_blocks_with_their_truth():
    rng = np.random.default_rng(0)
    shares = np.zeros((64, 3, 6, 6), dtype=np.float32)
    shares[:, 2] = 1.0
    truth = rng.random((64, 6, 6)) < 0.4
    inputs, mask = _reveal(shares, truth, 1.0, rng)
    shown = inputs[:, 2] == 0
    assert shown.any() and not (shown & mask).any() and np.array_equal(shown | mask, np.ones_like(mask))
    assert np.array_equal(inputs[:, 0][shown] == 1.0, truth[shown])
    unchanged, full_mask = _reveal(shares, truth, 0.0, rng)
    assert np.array_equal(unchanged, shares) and full_mask.all()


def test_training_learns_the_training_mazes(generated_maze_dir):
    collected = [block_snapshots(load_map(path), Protocol(), 5.0, every=2) for path in list_maps(generated_maze_dir)]
    samples = BlockSamples([s for s, _ in collected], [t for _, t in collected])
    config = BlockModelConfig(width=16, dilations=(1, 2, 1), groups=4)
    model, history = train_block_model(samples, samples, config, epochs=12, batch_size=32, lr=1e-2, reveal_share=0.0)
    assert [row["epoch"] for row in history] == list(range(1, 13))
    assert history[-1]["loss"] < 0.8 * history[0]["loss"]
    error, all_wall = block_error(model, samples)
    assert error < all_wall  # better than guessing every unknown block near the known map is wall
    assert history[-1]["held_out_error"] == error


def test_near_unknown_keeps_the_unknown_blocks_within_reach_of_known_free_ones():
    shares = np.zeros((1, 3, 9, 9), dtype=np.float32)
    shares[0, 2] = 1.0
    shares[0, :, 4, 4] = (1.0, 0.0, 0.0)  # one known free block in the middle
    near = near_unknown(shares, 2)[0]
    assert near.sum() == 24 and near[2, 2] and near[6, 6] and not near[1, 4] and not near[4, 4]


def test_a_killed_training_resumes_from_its_last_epoch_to_the_same_model(generated_maze_dir, tmp_path):
    import pytest
    import torch

    from pipeline.training.checkpoints import TrainingCheckpoint

    protocol = Protocol()
    config = BlockModelConfig(width=8, groups=4)
    maps = [load_map(p) for p in list_maps(generated_maze_dir)[:2]]
    collected = [block_snapshots(m, protocol, config.block_m, 6) for m in maps]
    samples = BlockSamples([s for s, _ in collected], [t for _, t in collected])
    whole, whole_history = train_block_model(samples, None, config, epochs=3, batch_size=16)

    class Killed(Exception):
        pass

    def kill_in_epoch_2(row):
        if row["epoch"] == 2:
            raise Killed  # before epoch 2 is saved: the checkpoint holds epoch 1

    checkpoint = TrainingCheckpoint(tmp_path, "settings-a")
    with pytest.raises(Killed):
        train_block_model(samples, None, config, epochs=3, batch_size=16, log=kill_in_epoch_2, checkpoint=checkpoint)
    epochs_run = []
    resumed, history = train_block_model(
        samples,
        None,
        config,
        epochs=3,
        batch_size=16,
        log=lambda row: epochs_run.append(row["epoch"]),
        checkpoint=checkpoint,
    )
    assert epochs_run == [2, 3] and [row["epoch"] for row in history] == [1, 2, 3]
    for a, b in zip(whole.state_dict().values(), resumed.state_dict().values()):
        assert torch.equal(a, b)
    assert [row["loss"] for row in history] == [row["loss"] for row in whole_history]
    # Other settings never resume from it.
    epochs_run.clear()
    train_block_model(
        samples,
        None,
        config,
        epochs=3,
        batch_size=16,
        log=lambda row: epochs_run.append(row["epoch"]),
        checkpoint=TrainingCheckpoint(tmp_path, "settings-b"),
    )
    assert epochs_run == [1, 2, 3]
