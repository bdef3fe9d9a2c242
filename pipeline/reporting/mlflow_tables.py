"""The result tables as DVC metrics (report.json) and as MLflow runs: one experiment per table,
one run per row, so variants compare side by side."""

from __future__ import annotations

from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np
import pandas as pd

from pipeline.common.mlflow_store import import_mlflow, log_maze_set, resolve_tracking_uri
from pipeline.reporting.tables import finite_number, sweep_label

TABLE_EXPERIMENTS: dict[str, str] = {
    "table1": "table1_inference",
    "table2": "table2_benchmark",
    "table3": "table3_ablation",
    "table4": "table4_denoising_steps",
    "table5": "table5_efficiency",
}
_ID_COLUMNS = ("planner", "K", "step", "label")


def _run_name(record: Mapping[str, Any]) -> str:
    if "step" in record and "planner" not in record:
        return f"step{int(record['step'])}"
    if "K" in record and record.get("K") is not None:
        return sweep_label(str(record["planner"]), int(record["K"]))
    return str(record["planner"])


def metrics_json(tables: Mapping[str, pd.DataFrame | None]) -> dict[str, dict[str, dict[str, float]]]:
    """{table: {row name: {numeric column: value}}}: our numbers only (the paper's constants
    and NaNs left out), the DVC metrics of report.json."""
    out: dict[str, dict[str, dict[str, float]]] = {}
    for key, table in tables.items():
        if table is None:
            continue
        rows: dict[str, dict[str, float]] = {}
        for record in table.to_dict("records"):
            values = {
                column: number
                for column, value in record.items()
                if column not in _ID_COLUMNS
                and not column.startswith("paper_")
                and not isinstance(value, (str, bool, np.bool_))
                and (number := finite_number(value)) is not None
            }
            if values:
                rows[_run_name(record)] = values
        out[key] = rows
    return out


def log_tables_to_mlflow(
    tables: Mapping[str, pd.DataFrame | None],
    tracking_uri: str | None = None,
    params: Mapping[str, Any] | None = None,
    artifacts: Mapping[str, Sequence[str | Path]] | None = None,
    maps: str | Path | None = None,
) -> dict[str, list[str]]:
    """One MLflow experiment per table, one run per row, so variants compare side by side.
    `maps`: the maze set the tables were measured on, each run's dataset input.

    Keys are "table1".."table4" (logged to table1_inference, table2_benchmark,
    table3_ablation, table4_denoising_steps) or experiment names. Run name: the planner,
    planner_kK for Table IV, stepN for Table I. Params: planner (and K / step) plus
    `params`; metrics: the row's finite numeric columns; text columns become tags; `artifacts`:
    per table key, files logged with each of its runs (Table V's coverage figure).
    Returns {experiment: [run ids]}.
    """
    mlflow = import_mlflow()

    mlflow.set_tracking_uri(resolve_tracking_uri(tracking_uri))
    run_ids: dict[str, list[str]] = {}
    for key, table in tables.items():
        if table is None:
            continue
        experiment = TABLE_EXPERIMENTS.get(key, key)
        mlflow.set_experiment(experiment)
        ids = run_ids.setdefault(experiment, [])
        for record in table.to_dict("records"):
            name = _run_name(record)
            with mlflow.start_run(run_name=name) as run:
                if maps is not None:
                    log_maze_set(maps, "evaluation")
                run_params = {
                    column: record[column] for column in _ID_COLUMNS if column in record and column != "label"
                }
                mlflow.log_params({**(dict(params) if params else {}), **run_params})
                metrics = {}
                tags = {"table": key}
                for column, value in record.items():
                    if column in _ID_COLUMNS:
                        continue
                    if isinstance(value, str):
                        tags[column] = value
                    elif isinstance(value, (bool, np.bool_)):
                        metrics[column] = float(value)
                    elif (number := finite_number(value)) is not None:
                        metrics[column] = number
                mlflow.set_tags(tags)
                if metrics:
                    mlflow.log_metrics(metrics)
                for path in (artifacts or {}).get(key, ()):
                    mlflow.log_artifact(str(path))
                ids.append(run.info.run_id)
    return run_ids
