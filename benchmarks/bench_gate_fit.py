"""Fit the sliver gate's perceptron on the samples a `fit_gate` run kept, and time it.

Usage: python benchmarks/bench_gate_fit.py [--samples checkpoints/gate_samples] [--batch 1024]
                                           [--passes 10] [--peak-lr 0.005]

Reads the per-map samples `dvc repro` keeps in checkpoints/gate_samples/ (maze maps first, then
office floors, as params.yaml's `fit_gate` counts them), fits on the same maps the stage fits on,
and prints the fit's seconds and, per family held out, the AUC and the shares of slivers and of
big targets that pass at the stage's threshold.
"""

from __future__ import annotations

import argparse
import pickle
import time
from pathlib import Path

import numpy as np
import yaml

from pipeline.models.sliver_gate import SliverGate, fit_perceptron, gate_inputs, roc_auc


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--samples", type=Path, default=Path("checkpoints/gate_samples"))
    parser.add_argument("--params", type=Path, default=Path("params.yaml"))
    parser.add_argument("--batch", type=int, default=1024)
    parser.add_argument("--passes", type=int, default=10)
    parser.add_argument("--peak-lr", type=float, default=0.005)
    args = parser.parse_args()
    section = yaml.safe_load(args.params.read_text())["fit_gate"]
    items = sorted(args.samples.glob("item_*.pkl"))
    if len(items) != section["maps"] + section["offices"]:
        raise SystemExit(
            f"error: {args.samples} holds {len(items)} maps' samples, fit_gate counts "
            f"{section['maps']} + {section['offices']}; run `dvc repro fit_gate` first"
        )
    samples = [pickle.loads(path.read_bytes()) for path in items]
    mazes, offices = samples[: section["maps"]], samples[section["maps"] :]
    fit = mazes[: -section["holdout_maps"]] + offices[: -section["office_holdout"]]
    held = {"mazes": mazes[-section["holdout_maps"] :], "offices": offices[-section["office_holdout"] :]}
    inputs = gate_inputs(np.concatenate([counts for counts, _ in fit]))
    labels = np.concatenate([gains for _, gains in fit]) >= section["min_gain"]
    started = time.perf_counter()
    layers = fit_perceptron(inputs, labels, tuple(section["hidden"]), 0, args.batch, args.passes, peak_lr=args.peak_lr)
    seconds = time.perf_counter() - started
    gate = SliverGate(layers, threshold=section["threshold"])
    print(f"{len(labels):,} samples, batch {args.batch} x {args.passes} passes, peak {args.peak_lr}: {seconds:.1f} s")
    for family, maps in held.items():
        counts = np.concatenate([c for c, _ in maps])
        big = np.concatenate([g for _, g in maps]) >= section["min_gain"]
        passes = gate.probability(counts) >= gate.threshold
        print(
            f"  {family} held out: AUC {roc_auc(gate.probability(counts), big):.4f}, slivers passed "
            f"{passes[~big].mean():.1%}, big passed {passes[big].mean():.1%}"
        )


if __name__ == "__main__":
    main()
