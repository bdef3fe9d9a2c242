"""The policy's sampling with the DDPM step made once per K against diffusers' own step, in one run.

Usage: python benchmarks/bench_sampling.py [--policy pipeline/assets/planner_guide.pt] [--k 30]
                                           [--candidates 8] [--repeats 200]

Loads an exported policy (the shipped maze policy by default; `pipeline/assets/real_robot/planner_guide.pt`
for the real robot's), traces its denoiser as the planners do, and times `sample` on one
encoded observation repeated `--candidates` times (a decision's batch), K steps, one torch
thread, alternating the two steps call by call so that the machine's drift falls on both. Checks
that both give the same sample, and prints the median and p95 of each and their ratio.
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import numpy as np
import torch

from pipeline.models.ddpm_update import DDPMUpdate
from pipeline.models.modeling_diffusion import load_policy


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", type=Path, default=Path("pipeline/assets/planner_guide.pt"))
    parser.add_argument("--k", type=int, default=30)
    parser.add_argument("--candidates", type=int, default=8)
    parser.add_argument("--repeats", type=int, default=200)
    args = parser.parse_args()
    torch.set_num_threads(1)
    policy, _ = load_policy(args.policy)
    policy.trace_denoiser()
    z = torch.randn(1, policy.config.obs_steps, policy.config.d_model, generator=torch.Generator().manual_seed(0))
    obs_z = z.expand(args.candidates, -1, -1)
    supports = DDPMUpdate.supports

    def sample(ours: bool) -> tuple[torch.Tensor, float]:
        DDPMUpdate.supports = staticmethod(supports if ours else (lambda scheduler: False))
        started = time.perf_counter()
        out = policy.sample(obs_z, num_inference_steps=args.k, generator=torch.Generator().manual_seed(1))
        return out, 1000 * (time.perf_counter() - started)

    for ours in (True, False):  # warm-up: the traces and the coefficients
        sample(ours)
    times: dict[bool, list[float]] = {True: [], False: []}
    same = True
    for _ in range(args.repeats):
        a, ta = sample(True)
        b, tb = sample(False)
        times[True].append(ta)
        times[False].append(tb)
        same &= bool(torch.equal(a, b))
    DDPMUpdate.supports = staticmethod(supports)
    ours, theirs = np.median(times[True]), np.median(times[False])
    print(f"{args.policy}: K={args.k}, {args.candidates} samples, one thread, {args.repeats} calls each")
    print(f"diffusers' step       {theirs:7.2f} ms median, {np.percentile(times[False], 95):7.2f} p95")
    print(f"DDPMUpdate            {ours:7.2f} ms median, {np.percentile(times[True], 95):7.2f} p95")
    print(f"ratio {ours / theirs:.2f}; the same samples: {same}")


if __name__ == "__main__":
    main()
