"""DVC stage: benchmark the configured planners on the test mazes.

Reads the `benchmark` section (planners, seed, workers) and the shared `protocol`
section of params.yaml. Writes docs/protocol.md's outputs under reports/benchmark/, the
DVC metrics file reports/benchmark.json, a PNG bar chart and a side-by-side trajectory
figure, and one MLflow run per planner.
"""

from __future__ import annotations

import json
from pathlib import Path

from pipeline.common.params import complete_section, load_params
from pipeline.common.paths import DATA, REPORTS
from pipeline.evaluation.benchmark import run_benchmark, summarise
from pipeline.reporting.render import render_comparison, save_png
from pipeline.reporting.tracking import log_benchmark
from pipeline.stage_runner import run_stage_main, stage_arguments
from pipeline.world.maps import list_maps, load_map
from pipeline.world.protocol import Protocol
from pipeline.world.trajectories import read_trajectory_csv

TEST_MAZES = DATA.mazes_test
OUT_DIR = REPORTS.benchmark
METRICS_PATH = REPORTS.benchmark_metrics
CHART_PATH = REPORTS.benchmark_chart
FIGURE_PATH = REPORTS.benchmark_figure


def read_params(params_path: str | Path) -> tuple[dict, Protocol]:
    params = load_params(params_path)
    section = complete_section(params, "benchmark", params_path, ("planners", "seed", "workers"))
    if not isinstance(section["planners"], list) or not section["planners"]:
        raise ValueError(f"{params_path}: the 'benchmark' section needs a 'planners' list")
    return section, Protocol.from_dict(params.get("protocol") or {})


def distance_chart(summary, path: Path) -> None:
    """Bar chart of mean distance (+- std) and completion per planner, as a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 3.2), dpi=120)
    names = list(summary.index)
    ax.barh(names, summary["distance_mean_m"], xerr=summary["distance_std_m"], color="#4c72b0", capsize=3)
    for y, (_, row) in enumerate(summary.iterrows()):
        ax.text(row.distance_mean_m + row.distance_std_m + 5, y, f"{row.distance_mean_m:.0f} m, {row.completion_rate * 100:.0f} % done", va="center", fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("distance to complete exploration (m), mean +- std over test mazes")
    ax.set_xlim(0, float((summary["distance_mean_m"] + summary["distance_std_m"]).max()) * 1.35)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)


def trajectory_figure(map_path: Path, frame, out_dir: Path, path: Path, protocol: Protocol) -> None:
    """The first test maze with every planner's path side by side."""
    ground_truth = load_map(map_path, cell_size=protocol.cell_size)
    rows = frame[frame["map"] == ground_truth.name]
    panels = [
        (row.planner, read_trajectory_csv(out_dir / row.planner / f"{ground_truth.name}.csv"), float(row.distance_m))
        for row in rows.itertuples()
    ]
    save_png(render_comparison(ground_truth, panels), path)


def main(params_path: str = "params.yaml") -> None:
    section, protocol = read_params(params_path)
    maps = list_maps(TEST_MAZES)
    if not maps:
        raise SystemExit(f"error: {TEST_MAZES}: no test mazes; run the generate_mazes stage first")
    frame = run_benchmark(
        maps, section["planners"], protocol, OUT_DIR, workers=section["workers"], seed=int(section["seed"])
    )
    summary = summarise(frame)
    METRICS_PATH.write_text(
        json.dumps(
            {
                planner: {
                    "distance_mean_m": round(float(row.distance_mean_m), 2),
                    "distance_std_m": round(float(row.distance_std_m), 2),
                    "completion_rate": round(float(row.completion_rate), 4),
                    "decision_ms_median": round(float(row.decision_ms_median), 3),
                }
                for planner, row in summary.iterrows()
            },
            indent=2,
        )
        + "\n"
    )
    distance_chart(summary, CHART_PATH)
    trajectory_figure(maps[0], frame, OUT_DIR, FIGURE_PATH, protocol)
    log_benchmark(frame, OUT_DIR, protocol, maps=str(TEST_MAZES), experiment="benchmark")
    print((OUT_DIR / "summary.md").read_text())


if __name__ == "__main__":
    run_stage_main(main, stage_arguments(__doc__).parse_args().params)
