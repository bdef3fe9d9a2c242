"""The block model the lookahead draws its imagined maps from (the `train_block_model` stage).

Draws its own mazes (maze i from seed [maze_seed, i], as `guide mazes` draws them): the block
model is a prior of one maze family and size. Runs gated `greedy_utility` on each, takes the
belief's block shares every `snapshot_every` steps with the maze's true blocks, trains the block
model on all but the last `holdout_mazes` and measures its error on those (the unknown blocks
near the known free space, where the lookahead draws its maps). Writes the model, its metrics and
a figure, and logs one MLflow run in experiment "block_model".
"""

from __future__ import annotations

import json
import tempfile
import time
from typing import Annotated, Any

import numpy as np
from pydantic import model_validator

from pipeline.common.atomic import atomic_write_json
from pipeline.common.config import Section, fraction, positive, real, whole
from pipeline.common.executor import run_tasks
from pipeline.common.fingerprints import settings_digest, source_digest
from pipeline.common.kept_results import KeptResults
from pipeline.common.mlflow_store import import_mlflow, log_generated_maze_set, resolve_tracking_uri
from pipeline.common.paths import CHECKPOINTS, REPORTS
from pipeline.models.configuration_block_model import BlockModelConfig
from pipeline.models.defaults import PIPELINE_BLOCK_MODEL
from pipeline.models.modeling_block_model import save_block_model
from pipeline.reporting.training_figures import block_model_training_figure
from pipeline.training.block_model import (
    BlockSamples,
    TrainingCheckpoint,
    block_error,
    block_snapshots,
    train_block_model,
)
from pipeline.world.maps import load_map
from pipeline.world.mazes import MazeConfig, generate_maze_set
from pipeline.world.protocol import Protocol

MODEL_PATH = PIPELINE_BLOCK_MODEL
METRICS_PATH = REPORTS.block_model
FIGURE_PATH = REPORTS.block_model_figure
EXPERIMENT = "block_model"
KEPT_SNAPSHOTS = CHECKPOINTS.block_snapshots
CHECKPOINT_DIR = CHECKPOINTS.block_model


class Settings(Section):
    """The `train_block_model` section of params.yaml."""

    mazes: Annotated[int, whole(1)]
    holdout_mazes: Annotated[int, whole(0)]
    side_m: Annotated[float, positive("metres")]
    maze_seed: Annotated[int, whole(0)]
    snapshot_every: Annotated[int, whole(1, note="steps")]
    epochs: Annotated[int, whole(1)]
    batch_size: Annotated[int, whole(1)]
    lr: Annotated[float, real(0.0)]
    reveal_share: Annotated[float, fraction()]
    model: BlockModelConfig
    workers: Annotated[int, whole(1)]
    seed: Annotated[int, whole(0)]

    @model_validator(mode="after")
    def _holdout_leaves_mazes_to_fit(self) -> "Settings":
        if not self.holdout_mazes < self.mazes:
            raise ValueError(f"holdout_mazes ({self.holdout_mazes}) must be below mazes ({self.mazes})")
        return self


def maze_config(settings: Settings, protocol: Protocol):
    """The mazes the model learns from: the benchmark's family at `side_m`, in the model's blocks."""
    side = settings.side_m
    return MazeConfig(side_m=(side, side), block_m=settings.model.block_m, cell_size=protocol.cell_size)


def _snapshots(task: tuple[str, dict, float, int]) -> tuple[np.ndarray, np.ndarray]:
    path, protocol, block_m, every = task
    return block_snapshots(load_map(path), Protocol.from_dict(protocol), block_m, every)


def train_the_block_model(settings: Settings, protocol: Protocol) -> dict[str, Any]:
    """Collect, train, measure and write the block model from the `train_block_model` settings;
    the metrics written."""
    started, config = time.perf_counter(), settings.model
    with tempfile.TemporaryDirectory() as folder:
        maps = generate_maze_set(maze_config(settings, protocol), settings.mazes, folder, seed=settings.maze_seed)
        tasks = [(str(m), protocol.to_dict(), config.block_m, settings.snapshot_every) for m in maps]
        # The mazes are drawn from these settings alone (their folder is a fresh temporary one each run).
        identity = {
            "mazes": settings.as_written("mazes", "side_m", "maze_seed", "snapshot_every"),
            "block_m": config.block_m,
            "protocol": protocol.to_dict(),
            "source": source_digest(),
        }
        collected = run_tasks(
            _snapshots, tasks, settings.workers, "block snapshots", "maze", keep=KeptResults(KEPT_SNAPSHOTS, identity)
        )
    fit_count = len(maps) - settings.holdout_mazes
    train = BlockSamples([s for s, _ in collected[:fit_count]], [t for _, t in collected[:fit_count]])
    held_out = BlockSamples([s for s, _ in collected[fit_count:]], [t for _, t in collected[fit_count:]])
    collect_seconds = time.perf_counter() - started
    fit_identity = {
        **identity,
        "fit": settings.as_written("holdout_mazes", "epochs", "batch_size", "lr", "reveal_share", "seed"),
        "model": config.to_dict(),
    }
    model, history = train_block_model(
        train,
        held_out,
        config,
        settings.epochs,
        settings.batch_size,
        settings.lr,
        settings.reveal_share,
        settings.seed,
        checkpoint=TrainingCheckpoint(CHECKPOINT_DIR, settings_digest(fit_identity)),
        log=lambda row: print(json.dumps({k: round(v, 4) for k, v in row.items()}), flush=True),
    )
    error, all_wall_error = block_error(model, held_out) if len(held_out) else (float("nan"), float("nan"))
    metrics: dict[str, Any] = {
        "mazes_fit": fit_count,
        "mazes_holdout": settings.holdout_mazes,
        "snapshots_fit": len(train),
        "snapshots_holdout": len(held_out),
        "held_out_error": round(error, 4)
        if len(held_out)
        else None,  # unknown blocks within 20 m of the known free space
        "held_out_error_all_wall": round(all_wall_error, 4) if len(held_out) else None,  # guessing "wall" there
        "history": [{k: round(v, 4) for k, v in row.items()} for row in history],
        "parameters": sum(p.numel() for p in model.parameters()),
    }
    save_block_model(
        model,
        MODEL_PATH,
        {
            "mazes": settings.as_written("mazes", "side_m", "maze_seed"),  # as the file names them
            "protocol": protocol.to_dict(),
            **{k: v for k, v in metrics.items() if k != "history"},
        },
    )
    metrics["collect_seconds"] = round(collect_seconds, 1)
    metrics["train_seconds"] = round(sum(row["seconds"] for row in history), 1)
    atomic_write_json(METRICS_PATH, metrics)
    example = None
    if len(held_out):
        shares = held_out.shares[0][len(held_out.shares[0]) // 3]
        example = (shares, model.free_probability(shares), held_out.truth[0])
    block_model_training_figure(history, example, FIGURE_PATH)
    log_run(settings, protocol, metrics, history)
    return metrics


def log_run(settings: Settings, protocol: Protocol, metrics: dict[str, Any], history: list[dict[str, float]]) -> None:
    mlflow = import_mlflow()
    mlflow.set_tracking_uri(resolve_tracking_uri(None))
    mlflow.set_experiment(EXPERIMENT)
    with mlflow.start_run(run_name="train_block_model"):
        drawn = settings.as_written("mazes", "side_m", "maze_seed")
        log_generated_maze_set(
            f"block model mazes ({settings.mazes} of {settings.side_m:g} m, seed {settings.maze_seed})",
            {"generator": "guide mazes", "count": drawn["mazes"], "side_m": drawn["side_m"]}
            | {"seed": drawn["maze_seed"], "block_m": settings.model.block_m},
        )
        mlflow.log_params(
            {
                **protocol.to_dict(),
                **{f"train_block_model.{k}": v for k, v in settings.as_written().items() if k != "model"},
                **{f"model.{k}": v for k, v in settings.model.to_dict().items()},
            }
        )
        mlflow.log_metrics(
            {k: float(v) for k, v in metrics.items() if isinstance(v, (int, float)) and not isinstance(v, bool)}
        )
        for row in history:
            mlflow.log_metrics(
                {"epoch_loss": row["loss"], "epoch_held_out_error": row["held_out_error"]}, step=int(row["epoch"])
            )
        for path in (MODEL_PATH, METRICS_PATH, FIGURE_PATH):
            if path.is_file():
                mlflow.log_artifact(str(path))
