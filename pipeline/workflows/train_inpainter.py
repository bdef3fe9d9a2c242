"""Stage I training and its report (the `train_inpainter` stage): the node-image inpainter trained
on the Stage I pairs, then measured on the held-out pairs: precision, recall and F1 of the
predicted free nodes per threshold, prediction time, training curves and sample predictions."""

from __future__ import annotations

import time
import warnings
from pathlib import Path
from typing import Any, Optional

import numpy as np

from pipeline.common.atomic import atomic_file, atomic_write_json
from pipeline.common.fingerprints import files_digest, settings_digest
from pipeline.common.paths import CHECKPOINTS, DATA, MODELS, REPORTS
from pipeline.data.shards import read_manifest
from pipeline.models import InpainterConfig, TracedInpainter
from pipeline.models.modeling_inpainter import load_inpainter, read_inpainter_export
from pipeline.training.inpainter import TrainConfig, train_inpainter
from pipeline.training.inpainter_data import split_pairs
from pipeline.training.inpainter_losses import evaluate_inpainter
from pipeline.training.run_setup import resume_point, start_afresh
from pipeline.world.protocol import Protocol

DATA_DIR = DATA.pairs
OUT_DIR = MODELS.inpainter
CHECKPOINT_DIR = CHECKPOINTS.inpainter
METRICS = REPORTS.inpainter
CURVES = REPORTS.inpainter_curves
SAMPLES = REPORTS.inpainter_samples
REPORT_THRESHOLDS = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)
RUN_KEYS = ("model", "accelerator", "devices", "init_checkpoint", "experiment", "threads")


def prediction_ms(model, size: int = 48, repeats: int = 50) -> float:
    """Median milliseconds of one single-image prediction (a module or a TracedInpainter)."""
    import torch

    image = np.full((size, size), 128, dtype=np.uint8)
    image[size // 2 - 2 : size // 2 + 2, 4 : size - 4] = 255
    batch = torch.from_numpy(image)[None, None]
    times = []
    with torch.inference_mode():
        for _ in range(5):
            model(batch)
        for _ in range(repeats):
            t0 = time.perf_counter()
            model(batch)
            times.append(time.perf_counter() - t0)
    return float(np.median(times) * 1e3)


def plot_curves(history: list[dict[str, float]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    epochs = [h["epoch"] + 1 for h in history]
    fig, (ax_loss, ax_val) = plt.subplots(1, 2, figsize=(10, 3.8))
    ax_loss.plot(epochs, [h["train_loss"] for h in history], label="train loss")
    ax_loss.plot(epochs, [h["val_loss"] for h in history], label="val loss")
    ax_loss.set_xlabel("epoch")
    ax_loss.set_ylabel("BCE (hole + weighted known)")
    ax_loss.legend()
    ax_loss.grid(alpha=0.3)
    for key, label in (("val_f1", "F1"), ("val_precision", "precision"), ("val_recall", "recall")):
        ax_val.plot(epochs, [h[key] for h in history], label=label, linewidth=2 if key == "val_f1" else 1)
    ax_val.set_xlabel("epoch")
    ax_val.set_ylabel("free nodes in unknown space (val)")
    ax_val.set_ylim(0, 1)
    ax_val.legend()
    ax_val.grid(alpha=0.3)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:
        fig.savefig(tmp, dpi=110)
    plt.close(fig)


def _node_rgb(image: np.ndarray, valid: np.ndarray) -> np.ndarray:
    rgb = np.zeros(image.shape + (3,), dtype=np.float32)
    rgb[image >= 192] = (1.0, 1.0, 1.0)
    rgb[(image > 63) & (image < 192)] = (0.55, 0.7, 0.9)  # unknown
    rgb[~valid] = (0.35, 0.35, 0.35)  # padding
    return rgb


def plot_samples(model, val_pairs: dict, threshold: float, path: Path, count: int = 6) -> None:
    """Rows of observed / predicted probability / hits at tau / ground truth for validation pairs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    samples = [(size, i) for size, group in sorted(val_pairs.items()) for i in range(len(group["observed"]))]
    picks = [samples[k] for k in np.linspace(0, len(samples) - 1, min(count, len(samples))).astype(int)]
    fig, axes = plt.subplots(len(picks), 4, figsize=(10, 2.6 * len(picks)), squeeze=False)
    cmap = plt.get_cmap("magma")
    for row, (size, i) in enumerate(picks):
        observed = val_pairs[size]["observed"][i]
        target = val_pairs[size]["target"][i]
        valid = val_pairs[size]["valid"][i]
        prob = model.predict(observed)
        hole = (observed > 63) & (observed < 192) & valid
        predicted = _node_rgb(observed, valid)
        predicted[hole] = cmap(prob[hole])[:, :3]
        hits = _node_rgb(observed, valid)
        hits[hole] = (0.1, 0.1, 0.1)
        free = target >= 192
        pred = (prob >= threshold) & hole
        hits[pred & free] = (0.1, 0.8, 0.2)  # true positive
        hits[pred & ~free] = (0.9, 0.1, 0.1)  # false positive
        hits[~pred & free & hole] = (1.0, 0.65, 0.0)  # missed
        truth = _node_rgb(np.where(free, 255, 0).astype(np.uint8), valid)
        tp, fp = int((pred & free).sum()), int((pred & ~free).sum())
        titles = ("observed", "predicted P(free) in unknown", f"at tau={threshold}: {tp} hit / {fp} false", "ground truth")
        for col, (image, title) in enumerate(zip((_node_rgb(observed, valid), predicted, hits, truth), titles)):
            ax = axes[row, col]
            ax.imshow(image, interpolation="nearest")
            ax.set_xticks([])
            ax.set_yticks([])
            if row == 0 or col == 2:
                ax.set_title(title, fontsize=8)
    fig.suptitle("validation pairs: white free, black obstacle, blue unknown, grey padding; "
                 "green hit, red false, orange missed", fontsize=8)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic_file(path) as tmp:
        fig.savefig(tmp, dpi=100)
    plt.close(fig)


def training_fingerprint(section: dict[str, Any], protocol: Protocol, accelerator: Any, devices: Any,
                         init_checkpoint: Optional[str]) -> str:
    """What the inpainter's weights depend on: its settings (not the MLflow experiment or the
    thread count), the device layout, the protocol, the pairs and the init checkpoint's bytes."""
    settings = {k: v for k, v in section.items() if k not in ("experiment", "threads", "init_checkpoint", "accelerator", "devices")}
    return settings_digest({"settings": settings, "accelerator": accelerator, "devices": devices,
                            "protocol": protocol.to_dict(), "pairs": files_digest([DATA_DIR]),
                            "init_checkpoint": files_digest([init_checkpoint]) if init_checkpoint else None})


def train_and_report(section: dict[str, Any], protocol: Protocol, accelerator: Optional[str] = None,
                     devices: Optional[int | str] = None, afresh: bool = False, init_checkpoint: Optional[str] = None,
                     tracking_uri: Optional[str] = None, progress: bool = False,
                     artifact_location: Optional[str] = None) -> dict[str, Any]:
    """Train the inpainter from the `train_inpainter` settings, then measure the export on the
    held-out pairs and write its metrics, curves and sample predictions; the metrics ({} in a
    process of a multi-device run other than the first).

    A run killed part-way continues from its last epoch's checkpoint in checkpoints/inpainter
    when the settings and data are the same (`afresh` starts over regardless)."""
    section = dict(section)
    accelerator = accelerator or section.get("accelerator") or "cpu"
    devices = devices if devices is not None else (section.get("devices") or 1)
    init_checkpoint = init_checkpoint or section.get("init_checkpoint")
    read_manifest(DATA_DIR)  # a finished data set, before any checkpoint is decided on
    fingerprint = training_fingerprint(section, protocol, accelerator, devices, init_checkpoint)
    run = {key: section.pop(key, None) for key in RUN_KEYS}
    train_config = TrainConfig.from_dict(section)
    model_config = InpainterConfig.from_dict(run["model"] or {})
    resume_from = None if afresh else resume_point(CHECKPOINT_DIR, fingerprint, "train_inpainter")
    if resume_from is None:
        start_afresh(CHECKPOINT_DIR, fingerprint)
    export_path = train_inpainter(
        model_config,
        DATA_DIR,
        OUT_DIR,
        train_config=train_config,
        accelerator=accelerator,
        devices=devices,
        resume=resume_from is not None,
        checkpoint_dir=CHECKPOINT_DIR,
        tracking_uri=tracking_uri,
        init_checkpoint=init_checkpoint,
        experiment_name=run["experiment"] or "inpainter",
        progress=progress,
        num_threads=run["threads"],
        artifact_location=artifact_location,
        protocol=protocol.to_dict(),
    )
    if export_path is None:  # another process of a multi-device run: rank zero exports and reports
        return {}
    export = read_inpainter_export(export_path)
    model, config = load_inpainter(export_path)
    if run["threads"]:
        import torch

        torch.set_num_threads(int(run["threads"]))
    with warnings.catch_warnings():  # the split training made: its warnings were shown then
        warnings.simplefilter("ignore")
        _, val_pairs = split_pairs(DATA_DIR, train_config.val_fraction, train_config.split, train_config.seed)
    tau = train_config.threshold
    results = evaluate_inpainter(model, val_pairs, sorted({tau, *REPORT_THRESHOLDS}))
    at_tau = results[tau]
    metrics = {
        "val_precision": round(at_tau["precision"], 4),
        "val_recall": round(at_tau["recall"], 4),
        "val_f1": round(at_tau["f1"], 4),
        "threshold": tau,
        "val_predicted_free": at_tau["predicted"],
        "val_actual_free": at_tau["actual"],
        "by_threshold": {f"{t:g}": {k: round(v, 4) if isinstance(v, float) else v for k, v in r.items()}
                         for t, r in results.items()},
        "num_parameters": int(export["num_parameters"]),
        "train_seconds": export["train_seconds"],
        "epochs": export["epochs"],
        "best_epoch": export["best_epoch"],
        "split": train_config.split,
        "train_pairs": export["pairs"]["train"],
        "val_pairs": export["pairs"]["val"],
        "train_mazes": export["mazes"]["train"],
        "val_mazes": export["mazes"]["val"],
        "predict_ms_48": round(prediction_ms(TracedInpainter(model)), 3),  # frozen trace, current threads
        "predict_ms_48_eager": round(prediction_ms(model), 3),
        "trained_on": export.get("trained_on"),  # torch build, CPU kernels, threads: weights differ across hosts
        "resumed_after_epochs": resume_from[1] if resume_from else None,  # None: trained in one go
    }
    atomic_write_json(METRICS, metrics)
    plot_curves(export["history"], CURVES)
    plot_samples(model, val_pairs, tau, SAMPLES)
    return metrics
