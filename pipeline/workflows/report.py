"""The paper's Tables I-V beside ours (the `report` stage): the denoising-steps sweep for Table IV, the tables,
reports/report.md, its metrics, a trajectory figure, the coverage curves, and one MLflow experiment per table.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Annotated

import pandas as pd

from pipeline.common.atomic import atomic_folder, atomic_write_text
from pipeline.common.config import Section, identifier, list_of, maybe, satisfies, text, whole
from pipeline.common.paths import CHECKPOINTS, DATA, REPORTS
from pipeline.evaluation.exploration_curves import EXPLORATION_CSV, SpeedModel, read_step_records
from pipeline.planners import planner_config
from pipeline.planners.specs import PlannerSpec
from pipeline.reporting.coverage_figure import coverage_figure
from pipeline.reporting.mlflow_tables import log_tables_to_mlflow, metrics_json
from pipeline.reporting.table_markdown import (
    report_markdown,
    table1_markdown,
    table2_markdown,
    table3_markdown,
    table4_markdown,
    table5_markdown,
)
from pipeline.reporting.tables import read_metrics, read_precision, sweep_label, table2, table3, table4, table5
from pipeline.reporting.trajectory_figure import trajectory_figure
from pipeline.workflows import table1
from pipeline.workflows.benchmark import benchmark_with_summary
from pipeline.workflows.stage_inputs import generated_maps
from pipeline.world.map_files import MapError
from pipeline.world.protocol import Protocol

TEST_MAZES = DATA.mazes_test
BENCHMARK_DIR = REPORTS.benchmark
METRICS_CSV = BENCHMARK_DIR / "metrics.csv"
EXPLORATION_PATH = BENCHMARK_DIR / EXPLORATION_CSV
PRECISION_CSV = REPORTS.predictor / table1.PRECISION_CSV
PRECISION_COMPARE_CSV = REPORTS.predictor / table1.COMPARE_CSV  # another inpainter, when eval_predictor ran one
PRECISION_DETAIL_CSV = REPORTS.predictor / table1.DETAIL_CSV  # the same rows with V_u split up
SWEEP_DIR = REPORTS.denoising_steps
TABLES_DIR = REPORTS.tables
REPORT_MD = REPORTS.report
REPORT_JSON = REPORTS.report_metrics
FIGURE_PATH = REPORTS.report_figure
COVERAGE_PATH = REPORTS.coverage_figure
TEAMS_JSON = REPORTS.teams_metrics  # the benchmark stage's team runs (empty when none were configured)
TEAM_COVERAGE = REPORTS.teams / "team_coverage.png"


LABEL = text(note="a planner's label in the benchmark")  # a label absent from the benchmark shows as "not run"


class Settings(Section):
    """The `report` section of params.yaml."""

    k_values: Annotated[list[int], list_of(whole(1), min_length=0)]  # [] (or no k_planners): no sweep, no Table IV
    k_planners: Annotated[list[str], list_of(satisfies(planner_config, "a registered planner name", str), min_length=0)]
    k_option: Annotated[str, identifier("a planner option name")]
    k_maps: Annotated[int, whole(1)]
    ablation_planners: Annotated[list[str], list_of(LABEL)]
    figure_planners: Annotated[list[str], list_of(LABEL)]
    workers: Annotated[int | None, maybe(whole(1), "all cores")]
    seed: Annotated[int, whole(0)]


def sweep_specs(planners, k_values, option: str) -> list[PlannerSpec]:
    """One labelled variant per (planner, K): label planner_kK, option {option: K}."""
    return [PlannerSpec(sweep_label(name, k), name, {option: k}) for name in planners for k in k_values]


def run_sweep(maps, settings: Settings, protocol: Protocol):
    """The denoising-steps sweep into reports/denoising_steps/ (None when no K or no planner), built
    in a temporary folder that replaces the folder as a whole when the sweep is done."""
    specs = sweep_specs(settings.k_planners, settings.k_values, settings.k_option)
    if not specs:
        return None
    try:
        with atomic_folder(SWEEP_DIR) as folder:
            return benchmark_with_summary(
                maps,
                specs,
                protocol,
                folder,
                workers=settings.workers,
                seed=settings.seed,
                keep_dir=CHECKPOINTS.denoising_steps,
            ).frame
    except KeyError as error:  # an unregistered planner name
        raise SystemExit(f"error: report.k_planners: {error.args[0]}") from None
    except ValueError as error:  # an option the planner does not take
        raise SystemExit(f"error: report.k_option: {error}") from None


def write_report(settings: Settings, protocol: Protocol):
    """The denoising-steps sweep, Tables I-V, the figures, reports/report.md and its metrics from the `report` settings."""
    if not METRICS_CSV.is_file():
        raise SystemExit(
            f"error: {METRICS_CSV} not found; run the benchmark stage first "
            "(`dvc repro benchmark` or `python -m stages.benchmark`)"
        )
    try:
        maps = generated_maps(TEST_MAZES, "test mazes")
    except MapError as error:
        raise SystemExit(f"error: {error}; run the generate_mazes stage first") from None

    frame = read_metrics(METRICS_CSV)
    sweep_maps = maps[: settings.k_maps]
    sweep = run_sweep(sweep_maps, settings, protocol)
    precision = read_precision(PRECISION_DETAIL_CSV)
    if precision is None:
        precision = read_precision(PRECISION_CSV)

    exploration = read_exploration(EXPLORATION_PATH)
    speed = SpeedModel(float(exploration["speed_mps"].iloc[0]))
    tables = {
        "table1": precision,
        "table2": table2(frame),
        "table3": table3(frame, settings.ablation_planners),
        "table4": table4(sweep, settings.k_values, settings.k_planners) if sweep is not None else None,
        "table5": table5(exploration),
    }
    precision_compare = read_precision(PRECISION_COMPARE_CSV)
    with atomic_folder(TABLES_DIR) as tables_dir:  # reports/tables/ appears with all five tables or not at all
        atomic_write_text(tables_dir / "table1.md", table1_markdown(precision, precision_compare))
        atomic_write_text(tables_dir / "table2.md", table2_markdown(tables["table2"]))
        atomic_write_text(tables_dir / "table3.md", table3_markdown(tables["table3"]))
        atomic_write_text(tables_dir / "table5.md", table5_markdown(tables["table5"], speed.speed_mps))
        coverage_figure(
            read_step_records(BENCHMARK_DIR, frame),
            COVERAGE_PATH,
            speed,
            title=f"Coverage curves on the {frame['map'].nunique()} test mazes: mean, band one standard deviation",
        )
        atomic_write_text(
            tables_dir / "table4.md",
            table4_markdown(tables["table4"])
            if tables["table4"] is not None
            else "## Table IV: denoising steps K\n\nnot run: report.k_values or report.k_planners is empty.\n",
        )

    benchmark_maps = sorted(str(m) for m in frame["map"].unique())
    map_order = {Path(p).stem: p for p in maps}
    figure_maps = [map_order[name] for name in benchmark_maps if name in map_order]
    try:
        trajectory_figure(figure_maps, frame, BENCHMARK_DIR, settings.figure_planners, FIGURE_PATH, protocol)
        figure = FIGURE_PATH.name
    except ValueError as error:
        raise SystemExit(f"error: report.figure_planners: {error}") from None

    atomic_write_text(
        REPORT_MD,
        report_markdown(
            tables["table2"],
            tables["table3"],
            tables["table4"],
            precision,
            maps=benchmark_maps,
            sweep_maps=[Path(p).stem for p in sweep_maps] if sweep is not None else (),
            protocol=protocol,
            params=settings.as_written(),  # as the file holds them
            figure=figure,
            precision_compare=precision_compare,
            table5_frame=tables["table5"],
            speed_mps=speed.speed_mps,
            coverage_figure=COVERAGE_PATH.name,
            teams=json.loads(TEAMS_JSON.read_text()) if TEAMS_JSON.is_file() else None,
            team_coverage_figure=(
                TEAM_COVERAGE.relative_to(REPORT_MD.parent).as_posix() if TEAM_COVERAGE.is_file() else None
            ),
        ),
    )
    metrics = metrics_json(tables)
    atomic_write_text(REPORT_JSON, json.dumps(metrics, indent=2, sort_keys=True) + "\n")
    log_tables_to_mlflow(
        tables,
        params={**protocol.to_dict(), "maps": str(TEST_MAZES), "benchmark_maps": len(benchmark_maps)},
        artifacts={"table5": [COVERAGE_PATH]},
        maps=TEST_MAZES,
    )
    print(REPORT_MD.read_text())
    return metrics


def read_exploration(path: Path) -> pd.DataFrame:
    """The benchmark stage's exploration.csv (SystemExit naming the stage to rerun when it is missing)."""
    if not path.is_file():
        raise SystemExit(
            f"error: {path} not found; rerun the benchmark stage (`dvc repro benchmark`), "
            "which writes it beside metrics.csv"
        )
    exploration = pd.read_csv(path)
    if exploration.empty or "speed_mps" not in exploration.columns:
        raise SystemExit(f"error: {path}: no planner rows or no speed_mps column; rerun the benchmark stage")
    return exploration
