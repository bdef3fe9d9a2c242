"""The inpainter's training data: Stage I node-image pairs split by maze, augmented, and batched by size.

Validation holds out whole mazes (a maze is recognised by its ground-truth image), about
`val_fraction` of the pairs: with few training mazes a network learns to recognise a maze from
its explored part and recall the rest, which a split that shares mazes would count as inference
(`split="rollout"` keeps the last pairs of each shard and size instead). Augmentation: the 8
flips / quarter turns of the square, and optionally (`hide_prob`) a random box of observations
turned back to unknown. A batch holds one image size (32, 40, 48).
"""

from __future__ import annotations

import hashlib
import warnings
from pathlib import Path
from typing import Iterator

import lightning as L
import numpy as np
import torch

from pipeline.data.pairs import load_pairs
from pipeline.data.shards import read_manifest

PairSet = dict[int, dict[str, np.ndarray]]  # {size: {"observed", "target", "valid"}}


# ----------------------------------------------------------------------------- data
def shard_files(data_dir: str | Path) -> list[Path]:
    """The shard files of a finished Stage I data set, in manifest order."""
    data_dir = Path(data_dir)
    return [data_dir / entry["file"] for entry in read_manifest(data_dir)["shards"]]


SPLITS = ("maze", "rollout")


def maze_ids(group: dict[str, np.ndarray]) -> list[str]:
    """Which maze each pair comes from: its ground-truth image (the whole lattice) identifies it."""
    return [hashlib.sha1(t.tobytes() + v.tobytes()).hexdigest()[:16] for t, v in zip(group["target"], group["valid"])]


def split_pairs(
    data_dir: str | Path, val_fraction: float = 0.2, split: str = "maze", seed: int = 0
) -> tuple[PairSet, PairSet]:
    """(train, val) pair sets.

    split="maze": whole mazes are held out (about `val_fraction` of the pairs), so the
    validation measures inference in unseen mazes, like the paper's test set; a maze is
    recognised by its ground-truth image. split="rollout": the last `val_fraction` of each
    (shard, size) group (pairs are stored in rollout order), which shares mazes with
    training and so also rewards remembering them.
    """
    if not 0.0 < val_fraction < 1.0:
        raise ValueError("val_fraction must lie strictly between 0 and 1")
    if split not in SPLITS:
        raise ValueError(f"split {split!r}: use one of {SPLITS}")
    groups = [(size, group) for path in shard_files(data_dir) for size, group in load_pairs([path]).items()]
    if split == "maze":
        ids = [maze_ids(group) for _, group in groups]
        counts: dict[str, int] = {}
        for group_ids in ids:
            for maze in group_ids:
                counts[maze] = counts.get(maze, 0) + 1
        if len(counts) < 2:
            warnings.warn(
                f"{data_dir}: pairs from a single maze; holding out the last pairs of each rollout group", stacklevel=2
            )
            return split_pairs(data_dir, val_fraction, "rollout", seed)
        goal = val_fraction * sum(counts.values())
        held: set[str] = set()
        held_count = 0
        for maze in np.random.default_rng(seed).permutation(sorted(counts)):
            if held_count >= goal:
                break
            if held_count + counts[maze] <= 1.5 * goal and len(held) < len(counts) - 1:
                held.add(maze)
                held_count += counts[maze]
        if not held:
            held.add(min(counts, key=counts.__getitem__))
        masks = [np.array([maze in held for maze in group_ids], dtype=bool) for group_ids in ids]
    else:
        masks = []
        for _, group in groups:
            count = len(group["observed"])
            n_val = int(round(count * val_fraction)) if count > 1 else 0
            masks.append(np.arange(count) >= count - n_val)
    train: dict[int, dict[str, list[np.ndarray]]] = {}
    val: dict[int, dict[str, list[np.ndarray]]] = {}
    for (size, group), is_val in zip(groups, masks):
        for target, select in ((train, ~is_val), (val, is_val)):
            if select.any():
                bucket = target.setdefault(size, {"observed": [], "target": [], "valid": []})
                for key in bucket:
                    bucket[key].append(group[key][select])
    join = lambda d: {s: {k: np.concatenate(v) for k, v in g.items()} for s, g in sorted(d.items())}  # noqa: E731
    train_set, val_set = join(train), join(val)
    if not train_set or not val_set:
        raise ValueError(f"{data_dir}: too few pairs for a train/validation split")
    return train_set, val_set


def maze_count(pairs: PairSet) -> int:
    return len({maze for group in pairs.values() for maze in maze_ids(group)})


def pair_count(pairs: PairSet) -> int:
    return int(sum(len(g["observed"]) for g in pairs.values()))


def dihedral(image: np.ndarray, k: int) -> np.ndarray:
    """One of the 8 symmetries of the square: rotate by k % 4 quarter turns, flip if k >= 4."""
    out = np.rot90(image, k % 4)
    return np.ascontiguousarray(out[:, ::-1] if k >= 4 else out)


def hide_box(observed: np.ndarray, valid: np.ndarray) -> np.ndarray:
    """An earlier view of the same exploration: the observations inside a random box (20-60 %
    of the side) turned back to unknown, so hidden corridor ends become hole pixels to predict.
    Padding (`valid` False) stays as it is: it marks where the map ends."""
    size = observed.shape[0]
    height, width = (int(v) for v in torch.randint(size // 5, 3 * size // 5 + 1, (2,)))
    top, left = int(torch.randint(0, size - height + 1, ())), int(torch.randint(0, size - width + 1, ()))
    out = observed.copy()
    box = out[top : top + height, left : left + width]
    box[valid[top : top + height, left : left + width]] = 128
    return out


class NodeImagePairDataset(torch.utils.data.Dataset):
    """(observed, target, valid) arrays of one pair set; `sizes[i]` is item i's image size."""

    def __init__(self, pairs: PairSet, augment: bool = False, hide_prob: float = 0.0) -> None:
        self.pairs = pairs
        self.augment = augment
        self.hide_prob = hide_prob
        self.index = [(size, i) for size, group in pairs.items() for i in range(len(group["observed"]))]
        self.sizes = np.array([size for size, _ in self.index], dtype=np.int64)

    def __len__(self) -> int:
        return len(self.index)

    def __getitem__(self, item: int):
        size, i = self.index[item]
        group = self.pairs[size]
        arrays = [group["observed"][i], group["target"][i], group["valid"][i]]
        if self.augment:
            k = int(torch.randint(0, 8, ()))
            arrays = [dihedral(a, k) for a in arrays]
        if self.hide_prob > 0 and float(torch.rand(())) < self.hide_prob:
            arrays[0] = hide_box(arrays[0], arrays[2].astype(bool))
        return tuple(torch.from_numpy(np.ascontiguousarray(a)) for a in arrays)


class SizeGroupedBatchSampler(torch.utils.data.Sampler):
    """Batches of one image size each; shuffled per epoch (`set_epoch`), split across ranks."""

    def __init__(
        self, sizes: np.ndarray, batch_size: int, shuffle: bool, seed: int = 0, rank: int = 0, world_size: int = 1
    ) -> None:
        self.sizes, self.batch_size, self.shuffle, self.seed = sizes, batch_size, shuffle, seed
        self.rank, self.world_size = rank, world_size
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def _batches(self) -> list[list[int]]:
        rng = np.random.default_rng([self.seed, self.epoch])
        batches = []
        for size in np.unique(self.sizes):
            members = np.nonzero(self.sizes == size)[0]
            if self.shuffle:
                members = rng.permutation(members)
            batches += [members[i : i + self.batch_size].tolist() for i in range(0, len(members), self.batch_size)]
        if self.shuffle:
            batches = [batches[i] for i in rng.permutation(len(batches))]
        if self.world_size > 1:  # every rank gets the same number of batches
            per_rank = len(batches) // self.world_size
            batches = batches[self.rank : per_rank * self.world_size : self.world_size]
        return batches

    def __iter__(self) -> Iterator[list[int]]:
        return iter(self._batches())

    def __len__(self) -> int:
        return len(self._batches())


# Lightning is imported here (not lazily): this module is the training entry point.


class InpainterDataModule(L.LightningDataModule):
    """Stage I shards -> size-grouped, augmented training batches and validation batches."""

    def __init__(
        self,
        data_dir: str | Path,
        batch_size: int = 16,
        val_fraction: float = 0.2,
        augment: bool = True,
        seed: int = 0,
        hide_prob: float = 0.0,
        split: str = "maze",
    ) -> None:
        super().__init__()
        self.data_dir, self.batch_size, self.val_fraction = Path(data_dir), batch_size, val_fraction
        self.augment, self.seed, self.hide_prob, self.split = augment, seed, hide_prob, split
        self.train_pairs: PairSet | None = None
        self.val_pairs: PairSet | None = None

    def setup(self, stage: str | None = None) -> None:
        if self.train_pairs is None:
            self.train_pairs, self.val_pairs = split_pairs(self.data_dir, self.val_fraction, self.split, self.seed)

    def _loader(self, pairs: PairSet, train: bool) -> torch.utils.data.DataLoader:
        dataset = NodeImagePairDataset(
            pairs, augment=self.augment and train, hide_prob=self.hide_prob if train else 0.0
        )
        rank, world = 0, 1
        trainer = getattr(self, "trainer", None)
        if trainer is not None:
            rank, world = trainer.global_rank, trainer.world_size
        sampler = SizeGroupedBatchSampler(
            dataset.sizes,
            self.batch_size,
            shuffle=train,
            seed=self.seed,
            rank=rank if train else 0,
            world_size=world if train else 1,
        )
        return torch.utils.data.DataLoader(dataset, batch_sampler=sampler, num_workers=0)

    def train_dataloader(self):
        return self._loader(self.train_pairs, train=True)

    def val_dataloader(self):
        return self._loader(self.val_pairs, train=False)
