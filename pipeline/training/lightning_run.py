"""The skeleton every Lightning training here shares (the inpainter's, the diffusion policy's).

A run is set up the same way whatever it learns (`RunOptions`: the device, the checkpoint
folder, resume, the MLflow run): `start` makes the folders and seeds every generator; `fit`
trains with the best and last checkpoints written atomically (old ones set aside until the new
run has one), the MLflow logger on `tracking_uri`, and the wall-clock cap; `export` writes the
model on rank zero only and logs it. What a training learns (its module, data and export
format) stays in its own module.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any, Optional, cast

import lightning as L
from lightning.pytorch.callbacks import ModelCheckpoint

from pipeline.common.atomic import atomic_write_text
from pipeline.common.config import config_dataclass, flag, text, validate, whole
from pipeline.common.mlflow_store import log_maze_set
from pipeline.training.run_setup import (
    DEVICES,
    LAST_CKPT,
    atomic_checkpoint_io,
    check_accelerator,
    fresh_checkpoints,
    log_export,
    make_trainer,
    max_time,
    mlflow_logger,
    quiet_checkpoint_folder,
    training_host,
)

BEST_NAME = "best"
MLFLOW_RUN_FILE = "mlflow_run_id"  # beside last.ckpt: the MLflow run a resumed training logs on into


@config_dataclass
class RunOptions:
    """Where and how a training runs, apart from what it learns.

    `checkpoint_dir` holds Lightning's `last.ckpt` and `best.ckpt` (default: `out_dir`, where the
    export goes); `resume` continues from `last.ckpt` when there is one, and in the MLflow run the
    interrupted one made (`mlflow_run_id` beside it). `devices` are per node and `num_nodes` the
    nodes of a multi-node run (DDP; each node started with Lightning's MASTER_ADDR, MASTER_PORT,
    NODE_RANK): each of the devices x num_nodes processes takes a batch of the training's
    `batch_size`, so the global batch is batch_size x devices x num_nodes, and the learning rate is
    the one given (raise it by hand when the global batch grows). MLflow logs to
    `tracking_uri` (default: $MLFLOW_TRACKING_URI or sqlite:///mlflow.db) in `experiment`;
    `artifact_location` is where a newly made experiment keeps its artifacts. Whether this
    machine has the accelerator and devices is checked when the options are made, before any
    file is touched or an MLflow run is made.
    """

    out_dir: Path
    checkpoint_dir: Optional[Path] = None
    accelerator: Annotated[str, text(note="Lightning's accelerator: cpu, gpu, auto")] = "cpu"
    devices: Annotated[int | list[int] | str, DEVICES] = 1
    num_nodes: Annotated[int, whole(1)] = 1
    resume: Annotated[bool, flag()] = False
    mlflow: Annotated[bool, flag()] = True
    tracking_uri: Optional[str] = None
    experiment: Annotated[str, text(note="an MLflow experiment")] = "training"
    run_name: Optional[str] = None
    artifact_location: Optional[str] = None
    progress: Annotated[bool, flag()] = False

    def __post_init__(self) -> None:
        if self.checkpoint_dir is None:
            object.__setattr__(self, "checkpoint_dir", self.out_dir)
        check_accelerator(self.accelerator, self.devices)

    @classmethod
    def from_dict(cls, values: dict[str, Any]) -> "RunOptions":
        """The options a training function's arguments name; a refused one is a one-line ValueError."""
        return validate(cls, values)

    @property
    def _checkpoints(self) -> Path:
        """`checkpoint_dir`, which is never None once made (`out_dir` by default)."""
        return cast(Path, self.checkpoint_dir)

    @property
    def last(self) -> Path:
        return self._checkpoints / LAST_CKPT

    def resume_from(self) -> Optional[str]:
        """The checkpoint a resumed run continues from (None: a fresh run)."""
        return str(self.last) if self.resume and self.last.is_file() else None


@dataclass
class FitResult:
    trainer: Any
    checkpoint: ModelCheckpoint
    logger: Any
    seconds: float


def start(run: RunOptions, seed: int) -> None:
    """The folders made, a resume with nothing to resume said, and every generator seeded."""
    run.out_dir.mkdir(parents=True, exist_ok=True)
    run._checkpoints.mkdir(parents=True, exist_ok=True)
    if run.resume and run.resume_from() is None:
        warnings.warn(f"resume asked but {run.last} does not exist: training from scratch", stacklevel=3)
    L.seed_everything(seed, workers=True, verbose=False)


def fit(
    run: RunOptions,
    module: L.LightningModule,
    *,
    monitor: str,
    mode: str,
    max_epochs: int,
    max_minutes: Optional[float],
    fit_args: dict[str, Any],
    trainer_options: dict[str, Any],
    hyperparams: Optional[dict[str, Any]] = None,
    unused_parameters: bool = False,
    data: Optional[Path] = None,
) -> FitResult:
    """Train `module` (`fit_args`: its datamodule or loaders), keeping the best checkpoint by
    `monitor` (`mode` min or max) and the last. `unused_parameters`: a multi-device run lets a step
    leave some parameters without gradients (the GAN's two steps). `data` (the data set's folder
    or file) is recorded as the MLflow run's dataset input, with its DVC hash."""
    checkpoint = ModelCheckpoint(
        dirpath=run.checkpoint_dir,
        filename=BEST_NAME,
        monitor=monitor,
        mode=mode,
        save_top_k=1,
        save_last=True,
        auto_insert_metric_name=False,
        enable_version_counter=False,
    )
    ckpt_path = run.resume_from()
    run_file = run._checkpoints / MLFLOW_RUN_FILE
    run_id = run_file.read_text().strip() if ckpt_path is not None and run_file.is_file() else None
    logger: Any = (
        mlflow_logger(run.experiment, run.run_name, run.tracking_uri, run.artifact_location, run_id)
        if run.mlflow
        else False
    )
    options = dict(
        max_epochs=max_epochs,
        max_time=max_time(max_minutes),
        accelerator=run.accelerator,
        devices=run.devices,
        num_nodes=run.num_nodes,
        logger=logger,
        callbacks=[checkpoint],
        default_root_dir=str(run.checkpoint_dir),
        enable_progress_bar=run.progress,
        enable_model_summary=False,
        num_sanity_val_steps=0,
        plugins=[atomic_checkpoint_io()],
        **trainer_options,
    )
    trainer = make_trainer(**options)
    if unused_parameters and trainer.world_size > 1:
        # Each of the GAN's two steps leaves one network without gradients, which DDP refuses by default.
        trainer = make_trainer(**options, strategy="ddp_find_unused_parameters_true")
    if logger and hyperparams:  # makes the MLflow run: only once the trainer accepted the settings
        logger.log_hyperparams(hyperparams)
    if logger and trainer.is_global_zero:
        if data is not None and run_id is None:
            log_maze_set(data, "training", run_id=logger.run_id, client=logger.experiment)
        atomic_write_text(run_file, logger.run_id + "\n")
    started = time.perf_counter()
    with fresh_checkpoints(run._checkpoints, fresh=ckpt_path is None), quiet_checkpoint_folder():
        trainer.fit(module, ckpt_path=ckpt_path, **fit_args)
    return FitResult(trainer, checkpoint, logger, time.perf_counter() - started)


def export(
    result: FitResult, path: Path, write: Callable[[dict[str, Any]], Any], num_parameters: int
) -> Optional[Path]:
    """`write(host)` writes the export at `path` on rank zero (the other ranks return None), then
    the MLflow run logs it with the training time and the host it was made on."""
    if not result.trainer.is_global_zero:
        return None
    host = training_host(result.trainer.strategy.root_device)
    write(host)
    if result.logger:
        log_export(result.logger, path, result.seconds, num_parameters, host)
    return path
