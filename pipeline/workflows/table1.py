"""Table I: the structural-inference precision of the node predictor on a folder of maps.

Explores each map with nearest_frontier, runs the Global Node Predictor with the inpainter at
each step and region evaluation, and writes precision.csv (with precision_detail.csv: V_u split
into predictions and centroids), table1.md (ours beside the paper's, and the precision at each
tau of a sweep), precision_by_threshold.csv, threshold_sweep.png and fig3.png; with a second
inpainter, Table I again with that network on the same explorations (precision_compare.csv and
a section of table1.md). What `guide eval-predictor` and the `eval_predictor` stage run.
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Optional

import pandas as pd

from pipeline.common.atomic import atomic_file, atomic_folder, atomic_write_text
from pipeline.common.mlflow_store import import_mlflow, log_maze_set, resolve_tracking_uri
from pipeline.evaluation.predictor_eval import (
    COLUMNS,
    PAPER_STEPS,
    SWEEP_THRESHOLDS,
    TABLE1_KEEP_SHARE,
    TABLE1_MIN_COMPONENT,
    TABLE1_THRESHOLD,
    evaluate_predictor,
    evaluate_with_sweep,
    load_inpaint_fn,
)
from pipeline.prediction.global_graph import GlobalGraphConfig, RegionEvaluationConfig
from pipeline.prediction.node_predictor import NodePredictorConfig
from pipeline.reporting.predictor_figures import plot_threshold_sweep, prediction_figure
from pipeline.reporting.table_markdown import comparison_markdown, sweep_markdown, table1_markdown
from pipeline.world.map_files import MapError
from pipeline.world.maps import list_maps, load_map
from pipeline.world.protocol import Protocol

EXPERIMENT = "table1"
PRECISION_CSV = "precision.csv"  # the columns
DETAIL_CSV = "precision_detail.csv"  # the same rows with V_u split into predictions and centroids
COMPARE_CSV = "precision_compare.csv"  # another inpainter on the same explorations


def run(
    maps_dir: str | Path,
    out_dir: str | Path,
    checkpoint: Optional[str],
    steps,
    predictor_config: NodePredictorConfig,
    protocol: Protocol,
    figure: bool = True,
    graph_config: GlobalGraphConfig = GlobalGraphConfig(),
    progress: bool = True,
    sweep_thresholds=(),
    start: tuple[float, float] | None = None,
) -> pd.DataFrame:
    """Evaluate on every map in `maps_dir`; writes precision.csv, precision_detail.csv, table1.md
    and (optionally) fig3.png; with `sweep_thresholds` also precision_by_threshold.csv,
    threshold_sweep.png and the sweep's table in table1.md, from the same explorations."""
    maps = list_maps(maps_dir)
    if not maps:
        raise MapError(maps_dir, "no maps in this folder (maze .png, .npy or ROS .yaml)")
    for path in maps:  # a malformed map, or a grid without a start, fails before the explorations
        load_map(path, start=start, cell_size=protocol.cell_size)
    inpaint = load_inpaint_fn(checkpoint)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if sweep_thresholds:
        frame, sweep = evaluate_with_sweep(
            maps,
            inpaint,
            sweep_thresholds,
            steps,
            predictor_config,
            graph_config,
            protocol,
            progress=progress,
            start=start,
        )
    else:
        frame, sweep = (
            evaluate_predictor(
                maps, inpaint, steps, predictor_config, graph_config, protocol, progress=progress, start=start
            ),
            None,
        )
    unreached = [int(row.step) for row in frame.itertuples(index=False) if row.maps == 0]
    if unreached:
        warnings.warn(
            f"no exploration reached step {', '.join(map(str, unreached))}: every episode completed "
            f"earlier, so there is nothing to count there (precision n/a); larger maps reach later steps",
            stacklevel=2,
        )
    with atomic_file(out_dir / PRECISION_CSV) as tmp:
        frame.to_csv(tmp, columns=list(COLUMNS), index=False)
    with atomic_file(out_dir / DETAIL_CSV) as tmp:
        frame.to_csv(tmp, index=False)
    table = table1_markdown(
        frame, title="Structural inference precision (paper Table I)", threshold=predictor_config.threshold, level=1
    )
    if sweep is not None:
        with atomic_file(out_dir / "precision_by_threshold.csv") as tmp:
            sweep.to_csv(tmp, index=False)
        plot_threshold_sweep(sweep, out_dir / "threshold_sweep.png")
        table += "\n" + sweep_markdown(sweep)
    atomic_write_text(out_dir / "table1.md", table)
    if figure:
        steps_sorted = sorted(int(s) for s in steps)
        figure_step = steps_sorted[min(1, len(steps_sorted) - 1)]  # the paper's Fig. 3 is mid-exploration
        for candidate in (figure_step, steps_sorted[0]):
            done = any(
                prediction_figure(
                    m,
                    candidate,
                    inpaint,
                    predictor_config,
                    graph_config,
                    protocol,
                    out_path=out_dir / "fig3.png",
                    start=start,
                )
                is not None
                for m in maps[:3]
            )
            if done:
                break
        else:
            warnings.warn(
                f"fig3.png not drawn: no exploration of the first maps reached step {steps_sorted[0]}", stacklevel=2
            )
    return frame


def log_run(frame: pd.DataFrame, out_dir: Path, params: dict[str, Any], protocol: Protocol, maps: str) -> str:
    """One MLflow run of Table I: `params` (the `eval_predictor` settings as the file names them),
    the protocol, the figures per step and the tables; its id."""
    mlflow = import_mlflow()

    mlflow.set_tracking_uri(resolve_tracking_uri(None))
    mlflow.set_experiment(EXPERIMENT)
    with mlflow.start_run(run_name="structural_inference") as active:
        log_maze_set(maps, "evaluation")
        mlflow.log_params({**protocol.to_dict(), **{f"eval_predictor.{k}": v for k, v in params.items()}, "maps": maps})
        metrics = {}
        for row in frame.itertuples(index=False):
            for name in (
                "precision",
                "predicted_nodes",
                "maps",
                "prediction_ms_median",
                "centroids",
                "predictions_precision",
            ):
                value = float(getattr(row, name))
                if value == value:  # skip NaN
                    metrics[f"{name}_step{row.step}"] = value
        if (out_dir / COMPARE_CSV).is_file():
            for row in pd.read_csv(out_dir / COMPARE_CSV).itertuples(index=False):
                if row.precision == row.precision:
                    metrics[f"compare_precision_step{row.step}"] = float(row.precision)
        mlflow.log_metrics(metrics)
        for name in (
            PRECISION_CSV,
            DETAIL_CSV,
            "table1.md",
            "fig3.png",
            "precision_by_threshold.csv",
            "threshold_sweep.png",
            COMPARE_CSV,
        ):
            if (out_dir / name).is_file():
                mlflow.log_artifact(str(out_dir / name))
        return active.info.run_id


def compare_with(
    checkpoint: Optional[str],
    maps_dir: str | Path,
    out_dir: str | Path,
    steps,
    predictor_config: NodePredictorConfig,
    graph_config: GlobalGraphConfig,
    protocol: Protocol,
) -> pd.DataFrame | None:
    """Table I with another inpainter export on the same explorations: precision_compare.csv (a header
    only when `checkpoint` is None, so the stage's outputs always exist) and a section of table1.md."""
    out_dir = Path(out_dir)
    if checkpoint is None:
        with atomic_file(out_dir / COMPARE_CSV) as tmp:
            pd.DataFrame(columns=list(COLUMNS)).to_csv(tmp, index=False)
        return None
    if not Path(checkpoint).is_file():
        raise FileNotFoundError(f"eval_predictor.compare_checkpoint: {checkpoint}: no inpainter export there")
    frame = evaluate_predictor(
        list_maps(maps_dir), load_inpaint_fn(checkpoint), steps, predictor_config, graph_config, protocol, progress=True
    )
    with atomic_file(out_dir / COMPARE_CSV) as tmp:
        frame.to_csv(tmp, columns=list(COLUMNS), index=False)
    table = out_dir / "table1.md"
    before = table.read_text(encoding="utf-8") if table.is_file() else ""
    atomic_write_text(table, before + "\n" + comparison_markdown(frame, f"Another inpainter: {checkpoint}"))
    return frame


def predictor_folder(
    maps_dir: str | Path,
    out_dir: str | Path,
    checkpoint: Optional[str],
    compare_checkpoint: Optional[str],
    steps,
    predictor_config: NodePredictorConfig,
    protocol: Protocol,
    graph_config: GlobalGraphConfig = GlobalGraphConfig(),
    sweep_thresholds=(),
) -> pd.DataFrame:
    """The `eval_predictor` stage's folder: `run` and then `compare_with`, both into a temporary folder
    that replaces `out_dir` as a whole once both are done, so a stage killed halfway leaves the
    previous folder (or none), never one run's precision.csv beside another's table1.md."""
    with atomic_folder(out_dir) as folder:
        frame = run(
            maps_dir,
            folder,
            checkpoint,
            steps,
            predictor_config,
            protocol,
            graph_config=graph_config,
            sweep_thresholds=sweep_thresholds,
        )
        compare_with(compare_checkpoint, maps_dir, folder, steps, predictor_config, graph_config, protocol)
    return frame


def table1_for_folder(
    maps_dir: str | Path,
    out_dir: str | Path,
    checkpoint: Optional[str] = None,
    sweep: bool = False,
    threshold: float = TABLE1_THRESHOLD,
    start: tuple[float, float] | None = None,
) -> pd.DataFrame:
    """`guide eval-predictor`: default steps and predictor settings at tau `threshold` (the planners'
    by default), OUT/precision.csv (+ table1.md, fig3.png; with `sweep` the same at SWEEP_THRESHOLDS)."""
    if not 0.0 <= threshold <= 1.0:
        raise ValueError(f"threshold (tau) must lie in [0, 1], got {threshold}")
    config = NodePredictorConfig(threshold=threshold, min_component=TABLE1_MIN_COMPONENT)
    return run(
        maps_dir,
        out_dir,
        checkpoint,
        PAPER_STEPS,
        config,
        Protocol(),
        graph_config=table1_graph_config(TABLE1_KEEP_SHARE),
        sweep_thresholds=SWEEP_THRESHOLDS if sweep else (),
        start=start,
    )


def table1_graph_config(keep_share: float) -> GlobalGraphConfig:
    """The global graph of Table I: region evaluation keeping the best `keep_share` of scored regions."""
    if not 0.0 < keep_share <= 1.0:
        raise ValueError(f"eval_predictor.keep_share must lie in (0, 1], got {keep_share}")
    return GlobalGraphConfig(region=RegionEvaluationConfig(keep_share=keep_share))
