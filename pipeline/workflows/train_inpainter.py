"""Stage I training and its report (the `train_inpainter` stage): the node-image inpainter trained
on the Stage I pairs, then measured on the held-out pairs: precision, recall and F1 of the
predicted free nodes per threshold, prediction time, training curves and sample predictions."""

from __future__ import annotations

import time
import warnings
from typing import TYPE_CHECKING, Any, Optional

import numpy as np
import pydantic

from pipeline.common.atomic import atomic_write_json
from pipeline.common.config import Section, fields_of, maybe, text, whole
from pipeline.common.fingerprints import files_digest, settings_digest
from pipeline.common.paths import CHECKPOINTS, DATA, MODELS, REPORTS
from pipeline.data.shards import read_manifest
from pipeline.models import InpainterConfig, TracedInpainter
from pipeline.models.modeling_inpainter import load_inpainter, read_inpainter_export
from pipeline.reporting.training_figures import inpainter_sample_predictions, inpainter_training_curves
from pipeline.training.inpainter import TrainConfig, train_inpainter
from pipeline.training.inpainter_data import split_pairs
from pipeline.training.inpainter_losses import evaluate_inpainter
from pipeline.training.run_setup import DEVICES, resume_point, start_afresh
from pipeline.world.protocol import Protocol

DATA_DIR = DATA.pairs
OUT_DIR = MODELS.inpainter
CHECKPOINT_DIR = CHECKPOINTS.inpainter
METRICS = REPORTS.inpainter
CURVES = REPORTS.inpainter_curves
SAMPLES = REPORTS.inpainter_samples
REPORT_THRESHOLDS = (0.3, 0.4, 0.5, 0.6, 0.7, 0.8, 0.9)


# The `train_inpainter` section: TrainConfig's fields and the run's own settings side by side.
# Every key may be left out: the stage trains with TrainConfig's and InpainterConfig's defaults.
if TYPE_CHECKING:

    class Settings(Section):
        """The `train_inpainter` section of params.yaml: the run's own settings as a checker reads them."""

        model: InpainterConfig
        accelerator: Optional[str]
        devices: Optional[int | list[int] | str]
        num_nodes: Optional[int]
        threads: Optional[int]
        init_checkpoint: Optional[str]
        experiment: Optional[str]

else:
    Settings = pydantic.create_model(
        "Settings",
        __base__=Section,
        __module__=__name__,
        __doc__="The `train_inpainter` section of params.yaml.",
        **fields_of(TrainConfig),
        model=(InpainterConfig, InpainterConfig()),  # its fields, or big_lama: true with overrides
        accelerator=(maybe(text(note="Lightning's accelerator: cpu, gpu, auto"), "cpu"), None),
        devices=(maybe(DEVICES, "1"), None),
        num_nodes=(maybe(whole(1, note="nodes of a multi-node DDP run"), "1"), None),
        threads=(maybe(whole(0, note="0: torch's default"), "torch's default"), None),
        init_checkpoint=(maybe(text(note="a Big-LaMa checkpoint or an inpainter export"), "random weights"), None),
        experiment=(maybe(text(note="an MLflow experiment"), "inpainter"), None),
    )


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


def training_fingerprint(
    settings: Settings, protocol: Protocol, accelerator: Any, devices: Any, init_checkpoint: Optional[str]
) -> str:
    """What the inpainter's weights depend on: its settings as the file names them (not the MLflow
    experiment or the thread count), the device layout, the protocol, the pairs and the init
    checkpoint's bytes."""
    ignored = ("experiment", "threads", "init_checkpoint", "accelerator", "devices")
    return settings_digest(
        {
            "settings": {k: v for k, v in settings.as_written().items() if k not in ignored},
            "accelerator": accelerator,
            "devices": devices,
            "protocol": protocol.to_dict(),
            "pairs": files_digest([DATA_DIR]),
            "init_checkpoint": files_digest([init_checkpoint]) if init_checkpoint else None,
        }
    )


def train_and_report(
    settings: Settings,
    protocol: Protocol,
    accelerator: Optional[str] = None,
    devices: Optional[int | list[int] | str] = None,
    afresh: bool = False,
    init_checkpoint: Optional[str] = None,
    tracking_uri: Optional[str] = None,
    progress: bool = False,
    artifact_location: Optional[str] = None,
) -> dict[str, Any]:
    """Train the inpainter from the `train_inpainter` settings, then measure the export on the
    held-out pairs and write its metrics, curves and sample predictions; the metrics ({} in a
    process of a multi-device run other than the first).

    A run killed part-way continues from its last epoch's checkpoint in checkpoints/inpainter
    when the settings and data are the same (`afresh` starts over regardless)."""
    accelerator = accelerator or settings.accelerator or "cpu"
    devices = devices if devices is not None else (settings.devices or 1)
    init_checkpoint = init_checkpoint or settings.init_checkpoint
    read_manifest(DATA_DIR)  # a finished data set, before any checkpoint is decided on
    fingerprint = training_fingerprint(settings, protocol, accelerator, devices, init_checkpoint)
    train_config = TrainConfig(**{name: getattr(settings, name) for name in fields_of(TrainConfig)})
    resume_from = None if afresh else resume_point(CHECKPOINT_DIR, fingerprint, "train_inpainter")
    if resume_from is None:
        start_afresh(CHECKPOINT_DIR, fingerprint)
    export_path = train_inpainter(
        settings.model,
        DATA_DIR,
        OUT_DIR,
        train_config=train_config,
        accelerator=accelerator,
        devices=devices,
        num_nodes=settings.num_nodes or 1,
        resume=resume_from is not None,
        checkpoint_dir=CHECKPOINT_DIR,
        tracking_uri=tracking_uri,
        init_checkpoint=init_checkpoint,
        experiment_name=settings.experiment or "inpainter",
        progress=progress,
        num_threads=settings.threads,
        artifact_location=artifact_location,
        protocol=protocol.to_dict(),
    )
    if export_path is None:  # another process of a multi-device run: rank zero exports and reports
        return {}
    export = read_inpainter_export(export_path)
    model, config = load_inpainter(export_path)
    if settings.threads:
        import torch

        torch.set_num_threads(settings.threads)
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
        "by_threshold": {
            f"{t:g}": {k: round(v, 4) if isinstance(v, float) else v for k, v in r.items()} for t, r in results.items()
        },
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
    inpainter_training_curves(export["history"], CURVES)
    inpainter_sample_predictions(model, val_pairs, tau, SAMPLES)
    return metrics
