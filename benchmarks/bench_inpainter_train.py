"""Time one training step of the inpainter (forward, backward, Adam) at each image size, on one
thread and on more, side by side in one run.

Usage: python benchmarks/bench_inpainter_train.py [--batch 16] [--threads 1 2] [--steps 40] [--params params.yaml]

A freshly initialised generator as `train_inpainter.model` of params.yaml configures it on
random node images; the weights do not change the cost. Prints the median milliseconds per
step for each size and thread count, and each thread count's ratio to the first.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch
import yaml

from pipeline.models import InpainterConfig, InpainterModel
from pipeline.prediction.node_image import PAD_SIZES


def step_ms(model: InpainterModel, optimizer: torch.optim.Optimizer, batch: torch.Tensor, steps: int) -> float:
    """Median milliseconds of one step, after three warm-up steps."""
    times = []
    for index in range(steps + 3):
        started = time.perf_counter()
        optimizer.zero_grad()
        model.forward_logits(batch).mean().backward()
        optimizer.step()
        if index >= 3:
            times.append(1000 * (time.perf_counter() - started))
    return float(np.median(times))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--batch", type=int, default=16, help="images per step (train_inpainter.batch_size)")
    parser.add_argument("--threads", type=int, nargs="+", default=[1, 2], help="torch CPU thread counts to compare")
    parser.add_argument("--steps", type=int, default=40, help="timed steps per size and thread count")
    parser.add_argument("--params", type=Path, default=Path("params.yaml"), help="whose train_inpainter.model to build")
    args = parser.parse_args()
    config = InpainterConfig.from_dict(yaml.safe_load(args.params.read_text())["train_inpainter"]["model"])
    rng = np.random.default_rng(0)
    for size in PAD_SIZES:
        batch = torch.as_tensor(rng.integers(-1, 2, (args.batch, 1, size, size)).astype(np.float32))
        row = []
        for threads in args.threads:
            torch.set_num_threads(threads)
            torch.manual_seed(0)
            model = InpainterModel(config)
            row.append(step_ms(model, torch.optim.Adam(model.parameters()), batch, args.steps))
        cells = "  ".join(f"{t} thread(s) {ms:6.1f} ms ({ms / row[0]:.2f})" for t, ms in zip(args.threads, row))
        print(f"{size} px, batch {args.batch}:  {cells}")


if __name__ == "__main__":
    main()
