"""Time single node-image predictions of the inpainter (the planner's per-decision cost).

Usage: python benchmarks/bench_inpainter.py [--model models/inpainter/inpainter.pt] [--size 48]
                                            [--repeats 200] [--threads 1] [--big-lama]
Without --model it times a freshly initialised default-config generator (the weights do
not change the cost). Prints the parameter count and the median / p95 milliseconds of
one (1, 1, S, S) prediction under torch.inference_mode, eager and as a frozen TorchScript
trace (`TracedInpainter`, what a planner should call).
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from pipeline.models import InpainterConfig, InpainterModel, TracedInpainter


def node_image(size: int, seed: int = 0) -> np.ndarray:
    """A plausible observed node image: a few explored corridors in unknown space."""
    rng = np.random.default_rng(seed)
    image = np.full((size, size), 128, dtype=np.uint8)
    for _ in range(4):
        row, col = rng.integers(4, size - 4, size=2)
        image[row, max(0, col - 6) : col + 6] = 255
        image[max(0, row - 6) : row + 6, col] = 255
    return image


def time_predictions(model, size: int, repeats: int, warmup: int = 20) -> np.ndarray:
    """Milliseconds of each of `repeats` single predictions by `model` (a module or a TracedInpainter)."""
    batch = torch.from_numpy(node_image(size))[None, None]
    times = []
    with torch.inference_mode():
        for _ in range(warmup):
            model(batch)
        for _ in range(repeats):
            t0 = time.perf_counter()
            model(batch)
            times.append(time.perf_counter() - t0)
    return np.array(times) * 1e3


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--model", type=Path, help="an exported inpainter.pt (default: a fresh default-config model)")
    parser.add_argument("--size", type=int, default=48, help="node image side (a multiple of 8)")
    parser.add_argument("--repeats", type=int, default=200)
    parser.add_argument("--threads", type=int, default=1, help="torch CPU threads")
    parser.add_argument("--big-lama", action="store_true", help="time the 51 M-parameter Big-LaMa layout instead")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    if args.model is not None:
        from pipeline.models.modeling_inpainter import load_inpainter

        model, config = load_inpainter(args.model)
        name = str(args.model)
    else:
        config = InpainterConfig.big_lama() if args.big_lama else InpainterConfig()
        model = InpainterModel(config).eval()
        name = "Big-LaMa layout" if args.big_lama else "default config"
    print(f"inpainter ({name}): {model.num_parameters():,} parameters; ngf {config.ngf}, {config.n_blocks} FFC blocks")
    for label, runner in (("eager", model), ("traced", TracedInpainter(model))):
        times = time_predictions(runner, args.size, args.repeats)
        print(
            f"{args.size}x{args.size} prediction, {label:>6}, {args.threads} thread(s): median {np.median(times):.3f} ms, "
            f"p95 {np.percentile(times, 95):.3f} ms, min {times.min():.3f} ms over {args.repeats} predictions"
        )


if __name__ == "__main__":
    main()
