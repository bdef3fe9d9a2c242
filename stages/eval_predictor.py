"""DVC stage: precision of structural inference on the test mazes (paper Table I and Fig. 3).

Reads only the `eval_predictor` section (steps, threshold, min_component, keep_share,
sweep_thresholds, checkpoint, compare_checkpoint) and the shared `protocol` section of params.yaml. Explores each
test maze with nearest_frontier, runs the Global Node Predictor with the trained inpainter at
each step and region evaluation, and writes reports/predictor/precision.csv (with
precision_detail.csv: V_u split into predictions and centroids), reports/predictor/table1.md
(ours beside the paper's, and the precision at each tau of `sweep_thresholds`),
reports/predictor/precision_by_threshold.csv, threshold_sweep.png and fig3.png; with
`compare_checkpoint` (by default the shipped inpainter, trained at the paper profile's scale)
Table I again with that network on the same explorations, reports/predictor/precision_compare.csv
and a section of table1.md, so a CPU-sized profile still shows where a larger model lands.
Logs one MLflow run in experiment "table1".
"""

from __future__ import annotations

import warnings
from pathlib import Path
from typing import Any, Optional

import pandas as pd

from pipeline.prediction.global_graph import GlobalGraphConfig, RegionEvaluationConfig
from pipeline.world.maps import MapError, list_maps, load_map
from pipeline.prediction.node_predictor import NodePredictorConfig
from pipeline.common.params import load_params
from pipeline.evaluation.predictor_eval import COLUMNS, SWEEP_THRESHOLDS, TABLE1_KEEP_SHARE, TABLE1_MIN_COMPONENT, TABLE1_THRESHOLD
from pipeline.world.protocol import Protocol
from pipeline.stage_errors import run_stage_main

TEST_MAZES = Path("data/mazes/test")
OUT_DIR = Path("reports/predictor")
EXPERIMENT = "table1"
SECTION_KEYS = {"steps", "threshold", "min_component", "keep_share", "sweep_thresholds", "checkpoint", "compare_checkpoint"}
COMPARE_CSV = "precision_compare.csv"


def read_params(params_path: str | Path) -> tuple[dict[str, Any], Protocol]:
    params = load_params(params_path)
    section = dict(params.get("eval_predictor") or {})
    unknown = set(section) - SECTION_KEYS
    if unknown:
        raise ValueError(f"{params_path}: unknown eval_predictor parameter(s): {sorted(unknown)}")
    section.setdefault("steps", [15, 30, 45, 60])
    section.setdefault("threshold", TABLE1_THRESHOLD)
    section.setdefault("min_component", TABLE1_MIN_COMPONENT)
    section.setdefault("keep_share", TABLE1_KEEP_SHARE)
    section.setdefault("checkpoint", None)
    section.setdefault("compare_checkpoint", None)
    section.setdefault("sweep_thresholds", list(SWEEP_THRESHOLDS))
    sweep = section["sweep_thresholds"]
    if sweep is None:
        section["sweep_thresholds"] = []
    elif not isinstance(sweep, list) or any(isinstance(t, bool) or not isinstance(t, (int, float)) or not 0 <= t <= 1
                                            for t in sweep):
        raise ValueError(f"{params_path}: eval_predictor.sweep_thresholds must be a list of numbers in [0, 1], got {sweep!r}")
    if not section["steps"]:
        raise ValueError(f"{params_path}: eval_predictor.steps must list at least one step")
    return section, Protocol.from_dict(params.get("protocol") or {})


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
    from pipeline.evaluation.predictor_eval import (
        evaluate_predictor,
        evaluate_with_sweep,
        load_inpaint_fn,
        plot_threshold_sweep,
        prediction_figure,
        sweep_markdown,
        table1_markdown,
    )

    maps = list_maps(maps_dir)
    if not maps:
        raise MapError(maps_dir, "no maps in this folder (maze .png, .npy or ROS .yaml)")
    for path in maps:  # a malformed map, or a grid without a start, fails before the explorations
        load_map(path, start=start, cell_size=protocol.cell_size)
    inpaint = load_inpaint_fn(checkpoint)
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    if sweep_thresholds:
        frame, sweep = evaluate_with_sweep(maps, inpaint, sweep_thresholds, steps, predictor_config, graph_config, protocol,
                                           progress=progress, start=start)
    else:
        frame, sweep = evaluate_predictor(maps, inpaint, steps, predictor_config, graph_config, protocol, progress=progress,
                                           start=start), None
    unreached = [int(row.step) for row in frame.itertuples(index=False) if row.maps == 0]
    if unreached:
        warnings.warn(f"no exploration reached step {', '.join(map(str, unreached))}: every episode completed "
                      f"earlier, so there is nothing to count there (precision n/a); larger maps reach later steps",
                      stacklevel=2)
    frame.to_csv(out_dir / "precision.csv", columns=list(COLUMNS), index=False)
    frame.to_csv(out_dir / "precision_detail.csv", index=False)
    table = table1_markdown(frame, threshold=predictor_config.threshold)
    if sweep is not None:
        sweep.to_csv(out_dir / "precision_by_threshold.csv", index=False)
        plot_threshold_sweep(sweep, out_dir / "threshold_sweep.png")
        table += "\n" + sweep_markdown(sweep)
    (out_dir / "table1.md").write_text(table)
    if figure:
        steps_sorted = sorted(int(s) for s in steps)
        figure_step = steps_sorted[min(1, len(steps_sorted) - 1)]  # the paper's Fig. 3 is mid-exploration
        for candidate in (figure_step, steps_sorted[0]):
            done = any(
                prediction_figure(m, candidate, inpaint, predictor_config, graph_config, protocol,
                                  out_path=out_dir / "fig3.png", start=start) is not None
                for m in maps[:3]
            )
            if done:
                break
        else:
            warnings.warn(f"fig3.png not drawn: no exploration of the first maps reached step {steps_sorted[0]}",
                          stacklevel=2)
    return frame


def log_run(frame: pd.DataFrame, out_dir: Path, section: dict[str, Any], protocol: Protocol, maps: str) -> str:
    from pipeline.common.mlflow_store import import_mlflow, resolve_tracking_uri

    mlflow = import_mlflow()

    mlflow.set_tracking_uri(resolve_tracking_uri(None))
    mlflow.set_experiment(EXPERIMENT)
    with mlflow.start_run(run_name="structural_inference") as active:
        mlflow.log_params({**protocol.to_dict(), **{f"eval_predictor.{k}": v for k, v in section.items()}, "maps": maps})
        metrics = {}
        for row in frame.itertuples(index=False):
            for name in ("precision", "predicted_nodes", "maps", "prediction_ms_median", "centroids",
                         "predictions_precision"):
                value = float(getattr(row, name))
                if value == value:  # skip NaN
                    metrics[f"{name}_step{row.step}"] = value
        if (out_dir / COMPARE_CSV).is_file():
            for row in pd.read_csv(out_dir / COMPARE_CSV).itertuples(index=False):
                if row.precision == row.precision:
                    metrics[f"compare_precision_step{row.step}"] = float(row.precision)
        mlflow.log_metrics(metrics)
        for name in ("precision.csv", "precision_detail.csv", "table1.md", "fig3.png", "precision_by_threshold.csv",
                     "threshold_sweep.png", COMPARE_CSV):
            if (out_dir / name).is_file():
                mlflow.log_artifact(str(out_dir / name))
        return active.info.run_id


def main(params_path: str = "params.yaml") -> pd.DataFrame:
    section, protocol = read_params(params_path)
    config = NodePredictorConfig(threshold=float(section["threshold"]), min_component=int(section["min_component"]))
    graph_config = table1_graph_config(float(section["keep_share"]))
    frame = run(TEST_MAZES, OUT_DIR, section["checkpoint"], section["steps"], config, protocol,
                graph_config=graph_config, sweep_thresholds=section["sweep_thresholds"])
    compare_with(section["compare_checkpoint"], TEST_MAZES, OUT_DIR, section["steps"], config, graph_config, protocol)
    log_run(frame, OUT_DIR, section, protocol, str(TEST_MAZES))
    print((OUT_DIR / "table1.md").read_text())
    return frame


def compare_with(checkpoint: Optional[str], maps_dir: str | Path, out_dir: str | Path, steps,
                 predictor_config: NodePredictorConfig, graph_config: GlobalGraphConfig, protocol: Protocol) -> pd.DataFrame | None:
    """Table I with another inpainter export on the same explorations: precision_compare.csv (a header
    only when `checkpoint` is None, so the stage's outputs always exist) and a section of table1.md."""
    from pipeline.evaluation.predictor_eval import comparison_markdown, evaluate_predictor, load_inpaint_fn

    out_dir = Path(out_dir)
    if checkpoint is None:
        pd.DataFrame(columns=list(COLUMNS)).to_csv(out_dir / COMPARE_CSV, index=False)
        return None
    if not Path(checkpoint).is_file():
        raise FileNotFoundError(f"eval_predictor.compare_checkpoint: {checkpoint}: no inpainter export there")
    frame = evaluate_predictor(list_maps(maps_dir), load_inpaint_fn(checkpoint), steps, predictor_config, graph_config,
                               protocol, progress=True)
    frame.to_csv(out_dir / COMPARE_CSV, columns=list(COLUMNS), index=False)
    with open(out_dir / "table1.md", "a") as table:
        table.write("\n" + comparison_markdown(frame, f"Another inpainter: {checkpoint}"))
    return frame


def cli_main(maps_dir: str | Path, out_dir: str | Path, checkpoint: Optional[str] = None, sweep: bool = False,
             threshold: float = TABLE1_THRESHOLD, start: tuple[float, float] | None = None) -> pd.DataFrame:
    """`guide eval-predictor`: default steps and predictor settings at tau `threshold` (the planners'
    by default), OUT/precision.csv (+ table1.md, fig3.png; with `sweep` the same at SWEEP_THRESHOLDS)."""
    from pipeline.evaluation.predictor_eval import PAPER_STEPS

    if not 0.0 <= threshold <= 1.0:
        raise ValueError(f"threshold (tau) must lie in [0, 1], got {threshold}")
    config = NodePredictorConfig(threshold=threshold, min_component=TABLE1_MIN_COMPONENT)
    return run(maps_dir, out_dir, checkpoint, PAPER_STEPS, config, Protocol(), graph_config=table1_graph_config(TABLE1_KEEP_SHARE),
               sweep_thresholds=SWEEP_THRESHOLDS if sweep else (), start=start)


def table1_graph_config(keep_share: float) -> GlobalGraphConfig:
    """The global graph of Table I: region evaluation keeping the best `keep_share` of scored regions."""
    if not 0.0 < keep_share <= 1.0:
        raise ValueError(f"eval_predictor.keep_share must lie in (0, 1], got {keep_share}")
    return GlobalGraphConfig(region=RegionEvaluationConfig(keep_share=keep_share))


if __name__ == "__main__":
    run_stage_main(main)
