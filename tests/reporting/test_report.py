"""Tests of the report tables (pipeline/reporting/tables.py, table_markdown.py, mlflow_tables.py), labelled planner variants in the
benchmark, and the report stage (stages/report.py) on a tiny setup built in tmp_path."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pandas as pd
import pytest
import yaml

from pipeline.evaluation.benchmark import run_benchmark
from pipeline.evaluation.exploration_curves import SpeedModel, episode_table, planner_table, step_record
from pipeline.evaluation.statistics import paired_difference
from pipeline.planners.specs import PlannerSpec, parse_planner_spec
from pipeline.planners.wrapper import innermost
from pipeline.reporting.mlflow_tables import log_tables_to_mlflow, metrics_json
from pipeline.reporting.table_markdown import (
    COMPARE_LABEL,
    report_markdown,
    table1_markdown,
    table2_markdown,
    table3_markdown,
    table4_markdown,
    team_table_markdown,
)
from pipeline.reporting.tables import table2, table3, table4
from pipeline.reporting.trajectory_figure import trajectory_figure
from pipeline.workflows.benchmark import benchmark_with_summary
from pipeline.world.maps import load_maze_png
from pipeline.world.protocol import Protocol
from pipeline.world.simulator import replay
from pipeline.world.trajectories import (
    METRICS_COLUMNS,
    read_trajectory_csv,
    steps_path,
    write_metrics_csv,
    write_steps_csv,
    write_trajectory_csv,
)


# --------------------------------------------------------------------------- planner specs
@pytest.mark.parametrize(
    "text, expected",
    [
        ("nearest_frontier", PlannerSpec("nearest_frontier", "nearest_frontier", {})),
        (" guide ", PlannerSpec("guide", "guide", {})),
        ("fast=guide", PlannerSpec("fast", "guide", {})),
        ("guide_k10=guide:num_inference_steps=10", PlannerSpec("guide_k10", "guide", {"num_inference_steps": 10})),
        (
            "v-1.b=dare:eta=0.5,deterministic=True,mode=fast,flag=false,n=-3",
            PlannerSpec("v-1.b", "dare", {"eta": 0.5, "deterministic": True, "mode": "fast", "flag": False, "n": -3}),
        ),
        # null: the option's default meaning, as params.yaml writes it (guide's clustered tour, say)
        ("clusters=guide:spread=null,beta=1.5", PlannerSpec("clusters", "guide", {"spread": None, "beta": 1.5})),
    ],
)
def test_parse_planner_spec_good(text, expected):
    spec = parse_planner_spec(text)
    assert spec == expected and spec.options == expected.options
    assert [type(v) for v in spec.options.values()] == [type(v) for v in expected.options.values()]


def test_planner_spec_round_trips_through_str():
    for text in ("guide", "guide_k10=guide:num_inference_steps=10", "a=b:x=1,y=0.5", "c=guide:spread=null"):
        assert parse_planner_spec(str(parse_planner_spec(text))) == parse_planner_spec(text)


@pytest.mark.parametrize(
    "text, message",
    [
        ("", "empty planner spec"),
        ("guide:num_inference_steps=10", "needs a label"),
        ("=guide", "label ''"),
        ("a/b=guide", "label 'a/b'"),
        ("k10=", "planner name ''"),
        ("k10=Guide", "planner name 'Guide'"),
        ("k10=guide:", "nothing after ':'"),
        ("k10=guide:steps", "not key=value"),
        ("k10=guide:steps=", "not key=value"),
        ("k10=guide:steps=1,", "not key=value"),
        ("k10=guide:1x=2", "not an identifier"),
        ("k10=guide:a=1,a=2", "given twice"),
    ],
)
def test_parse_planner_spec_bad(text, message):
    with pytest.raises(ValueError, match=message.replace("(", r"\(")):
        parse_planner_spec(text)


@pytest.mark.parametrize(
    "planners, error, message",
    [
        (["x=no_such_planner:a=1"], KeyError, "unknown planner"),
        (
            ["x=nearest_frontier:no_such_option=1"],
            ValueError,
            "has no option no_such_option; it accepts: min_utility, sliver_gate, gate_file$",
        ),
        (
            ["x=guide:k=1"],
            ValueError,
            "guide has no option k; it accepts: .*num_inference_steps.*beta",
        ),  # the tour options too
        (["x=guide:prior_weight=abc"], ValueError, "option prior_weight='abc' must be a number"),
        (["x=guide:num_inference_steps=2.5"], ValueError, "option num_inference_steps=2.5 must be an integer"),
        (
            ["x=guide:num_inference_steps=0"],
            ValueError,
            r"num_inference_steps: must be a whole number >= 1, or null \(the policy's own\), got 0",
        ),
        (["x=expert:replan_on_change=1"], ValueError, "replan_on_change=1 must be true or false"),
        (["x=guide_tsp:inpaint=zeros"], ValueError, "'inpaint' takes a Python object"),
        (["x=guide_tsp:spread=-1"], ValueError, "'x'.*spread: must be a finite number >= 0"),
        (
            ["x=guide_tsp:beta=null"],
            ValueError,
            "'x'.*beta: must be a finite number >= 0, got None",
        ),  # null where none is meant
        (["x=guide_tsp:spread=2:beta=3"], ValueError, "separated by ','"),  # a ':' where a ',' belongs
        (["nearest_frontier", "nearest_frontier=greedy_utility"], ValueError, "used twice"),
        # an oracle bound passes the options it does not take to its base planner, and only those
        (
            ["x=oracle_tail:base=nearest_frontier,beta=1"],
            ValueError,
            "oracle_tail has no option beta; it accepts: base, handover_cells, min_utility",
        ),
        (["x=oracle_gate:base=guide_tsp,beta=abc"], ValueError, "option beta='abc' must be a number"),
        (
            ["x=oracle_gate:base=no_such_planner"],
            ValueError,
            "base: must be a lattice planner .*unknown planner 'no_such_planner'",
        ),
    ],
)
def test_run_benchmark_rejects_bad_variants_up_front(small_maze_path, tmp_path, planners, error, message):
    with pytest.raises(error, match=message):
        run_benchmark([small_maze_path], planners, Protocol(), tmp_path)
    assert not (tmp_path / "metrics.csv").exists()


def test_oracle_bound_specs_reach_their_base_planner():
    from pipeline.planners.specs import build_planner, resolve_planner_specs

    (spec,) = resolve_planner_specs(["t=oracle_tail:base=greedy_utility,sliver_gate=true,handover_cells=10"])
    planner = build_planner(spec)
    assert planner.handover_cells == 10 and innermost(planner.base).gate is not None  # sliver_gate went to the base


def test_run_benchmark_with_labelled_variant(small_maze_path, tmp_path):
    frame = benchmark_with_summary(
        [small_maze_path],
        ["nearest_frontier", "nf_u1=nearest_frontier:min_utility=1"],
        Protocol(),
        tmp_path,
        workers=2,
        progress=False,
    ).frame
    metrics = pd.read_csv(tmp_path / "metrics.csv")
    assert list(metrics.columns) == METRICS_COLUMNS
    assert sorted(metrics["planner"]) == ["nearest_frontier", "nf_u1"]
    assert set(frame["planner"]) == {"nearest_frontier", "nf_u1"}
    for label in ("nearest_frontier", "nf_u1"):
        points = read_trajectory_csv(tmp_path / label / "small.csv")
        assert tuple(points[0]) == (0.0, 0.0)
    assert not (tmp_path / "nearest_frontier" / "nf_u1").exists()
    assert "| nf_u1 |" in (tmp_path / "summary.md").read_text()


# --------------------------------------------------------------------------- tables
def metrics_rows(planner: str, distances, complete=None, ms=None, p95=None) -> list[dict]:
    n = len(distances)
    complete = complete or [True] * n
    ms = ms or [1.0] * n
    p95 = p95 or [2.0] * n
    return [
        {
            "map": f"maze_{i:04d}",
            "planner": planner,
            "distance_m": float(d),
            "steps": 10,
            "complete": c,
            "explored_ratio": 1.0,
            "decision_ms_median": m,
            "decision_ms_p95": p,
            "seed": 0,
        }
        for i, (d, c, m, p) in enumerate(zip(distances, complete, ms, p95))
    ]


@pytest.fixture
def bench_frame() -> pd.DataFrame:
    return pd.DataFrame(
        metrics_rows("optimal", [100, 100], ms=[0.5, 0.7])
        + metrics_rows("guide", [110, 120], ms=[3.0, 5.0], p95=[4.0, 8.0])
        + metrics_rows("nearest_frontier", [150, 130], complete=[True, False])
        + metrics_rows("guide_tsp", [125, 125])
    )


def test_table2_gap_and_paper_columns(bench_frame):
    table = table2(bench_frame)
    assert list(table["planner"]) == ["optimal", "guide", "guide_tsp", "nearest_frontier"]  # by distance
    guide = table.set_index("planner").loc["guide"]
    assert guide.distance_mean_m == 115.0 and guide.distance_std_m == 5.0
    assert guide.gap_to_optimal == pytest.approx(0.15)
    assert guide.decision_ms_median == 4.0 and guide.decision_ms_p95 == 6.0
    assert (guide.paper_row, guide.paper_distance_m, guide.paper_gap_pct) == ("GUIDE", 545.0, 8.8)
    rows = table.set_index("planner")
    assert rows.loc["optimal", "gap_to_optimal"] == 0.0 and np.isnan(rows.loc["optimal", "paper_gap_pct"])
    assert rows.loc["nearest_frontier", "completion_rate"] == 0.5
    assert rows.loc["nearest_frontier", "gap_to_optimal"] == pytest.approx(0.4)
    assert rows.loc["nearest_frontier", "paper_row"] == "—" and np.isnan(
        rows.loc["nearest_frontier", "paper_distance_m"]
    )
    assert (rows.loc["guide_tsp", "paper_distance_m"], rows.loc["guide_tsp", "paper_source"]) == (580.0, "Table III")
    text = table2_markdown(table)
    assert "| guide | GUIDE | 2 | 115.0 +- 5.0 | +15.0 % | — | 100 % | 4.00 | 545 | 8.8 % |" in text
    assert "| nearest_frontier | — | 2 | 140.0 +- 10.0 | +40.0 % | — | 50 % | 1.00 | — | — |" in text
    assert (
        "| guide_tsp | w/o diffusion | 2 | 125.0 +- 0.0 | +25.0 % | — | 100 % | 1.00 | 580 (Table III) | 15.7 % |"
        in text
    )
    assert table2_markdown(bench_frame) == text  # a raw metrics frame works too


def test_table2_paired_difference_to_greedy_utility():
    frame = pd.DataFrame(
        metrics_rows("greedy_utility", [100, 200, 300])
        + metrics_rows("guide", [90, 170, 280])  # 10, 30, 20 m shorter
        + metrics_rows("guide_tsp", [120])  # one shared map only
    )
    mean, half, maps = paired_difference(frame, "guide", "greedy_utility")
    assert maps == 3 and mean == pytest.approx(-20 / 200)
    assert half == pytest.approx(4.3027 * 10 / np.sqrt(3) / 200, rel=1e-4)  # std of (-10, -30, -20) is 10; t(2 dof)
    assert paired_difference(frame, "guide_tsp", "greedy_utility")[::2] == (pytest.approx(0.2), 1)
    assert np.isnan(paired_difference(frame, "guide_tsp", "greedy_utility")[1])  # no interval from one map
    assert np.isnan(paired_difference(frame, "optimal", "greedy_utility")[0])  # did not run
    text = table2_markdown(frame)
    assert "| guide | GUIDE | 3 | 180.0 +- 77.9 | — | -10.0 % +- 12.4 |" in text
    assert "| greedy_utility | — | 3 | 200.0 +- 81.6 | — | — |" in text
    assert "| guide_tsp | w/o diffusion | 1 | 120.0 | — | +20.0 % |" in text  # one episode: no spread
    assert "120.0 |" in table3_markdown(table3(frame)) and "+- 0.0" not in table3_markdown(table3(frame))


def test_table2_without_optimal_has_no_gap(bench_frame):
    table = table2(bench_frame[bench_frame["planner"] != "optimal"])
    assert table["gap_to_optimal"].isna().all()
    assert "No `optimal` episodes" in table2_markdown(table)


def test_table2_names_missing_columns():
    with pytest.raises(ValueError, match="missing column"):
        table2(pd.DataFrame({"planner": ["a"]}))


def test_table3_marks_missing_planners_not_run(bench_frame):
    table = table3(bench_frame)
    assert list(table["planner"]) == ["guide", "guide_noregion", "guide_tsp", "dare"]
    rows = table.set_index("planner")
    assert list(table["status"]) == ["ok", "not run", "ok", "not run"]
    assert rows.loc["guide_tsp", "gap_to_optimal"] == pytest.approx(0.25)
    assert (rows.loc["guide_noregion", "paper_row"], rows.loc["guide_noregion", "paper_distance_m"]) == (
        "w/o region evaluation",
        561.0,
    )
    assert rows.loc["dare", "paper_source"] == "Table II" and rows.loc["dare", "paper_distance_m"] == 565.0
    assert np.isnan(rows.loc["dare", "distance_mean_m"]) and rows.loc["dare", "episodes"] == 0
    text = table3_markdown(table)
    assert "| guide_noregion | w/o region evaluation | not run | — | — | — | 561 | 11.9 % |" in text
    assert "| dare | DARE | not run | — | — | — | 565 (Table II) | 12.8 % |" in text
    assert "| guide_tsp | w/o diffusion | 125.0 +- 0.0 | +25.0 % | 100 % | 1.00 | 580 | 15.7 % |" in text


def test_table4_from_sweep():
    sweep = pd.DataFrame(
        metrics_rows("guide_k10", [120, 130], ms=[10.0, 30.0], p95=[20.0, 40.0])
        + metrics_rows("guide_k30", [110, 110], ms=[50.0, 70.0], p95=[60.0, 100.0])
        + metrics_rows("dare_k10", [200], complete=[False], ms=[8.0], p95=[9.0])
        + metrics_rows("nearest_frontier", [99])  # not part of the sweep
    )
    table = table4(sweep, [10, 30])
    assert list(zip(table["planner"], table["K"])) == [("guide", 10), ("guide", 30), ("dare", 10), ("dare", 30)]
    rows = table.set_index("label")
    assert rows.loc["guide_k10", "decision_ms_median"] == 20.0 and rows.loc["guide_k10", "decision_ms_p95"] == 30.0
    assert rows.loc["guide_k30", "decision_ms_p95"] == 80.0 and rows.loc["guide_k30", "distance_mean_m"] == 110.0
    assert rows.loc["guide_k10", "paper_decision_s"] == 0.177 and rows.loc["guide_k30", "paper_distance_m"] == 533.0
    assert rows.loc["dare_k10", "completion_rate"] == 0.0 and rows.loc["dare_k10", "paper_distance_m"] == 762.0
    assert rows.loc["dare_k30", "status"] == "not run" and rows.loc["dare_k30", "episodes"] == 0
    text = table4_markdown(table)
    assert "| guide | 10 | 2 | 20.00 | 30.00 | 125.0 | 100 % | 0.177 | 579 |" in text
    assert "| dare | 30 | 0 | not run | — | — | — | 0.211 | 747 |" in text
    # K values the paper did not measure have no paper numbers
    other = table4(sweep, [5], planners=["guide"])
    assert other.loc[0, "status"] == "not run" and np.isnan(other.loc[0, "paper_decision_s"])


def precision_frame() -> pd.DataFrame:
    return pd.DataFrame(
        {
            "step": [15, 30],
            "precision": [0.8, 0.9],
            "predicted_nodes": [10, 20],
            "maps": [2, 2],
            "prediction_ms_median": [5.0, 6.0],
            "centroids": [1, 0],
            "predictions_precision": [0.85, 0.9],
        }
    )


def test_table1_reads_a_precision_csv_from_before_the_centroid_columns():
    old = precision_frame().drop(columns=["centroids", "predictions_precision"])
    text = table1_markdown(old)
    assert "| 15 | 80.00 % | 75.92 % | n/a | 10 | n/a | n/a | 2 | 5.00 |" in text
    assert "| 15 | 80.00 % | 75.92 % | n/a | 10 | 1 | 85.00 % | 2 | 5.00 |" in table1_markdown(precision_frame())


def test_table1_adds_another_inpainters_rows_when_compared():
    """precision_compare.csv: its rows after ours, each saying whether it reaches the paper's step."""
    compare = pd.DataFrame(
        {
            "step": [15, 30],
            "precision": [0.8, 0.7],
            "predicted_nodes": [10, 20],
            "maps": [2, 2],
            "prediction_ms_median": [3.0, 3.5],
        }
    )
    text = table1_markdown(precision_frame(), compare)
    assert text.index("Table I: structural inference precision") < text.index(COMPARE_LABEL)
    assert "| 15 | 80.00 % | 75.92 % | yes | 5.0 | 3.00 |" in text
    assert "| 30 | 70.00 % | 79.73 % | no | 10.0 | 3.50 |" in text
    # an empty file (eval_predictor ran no comparison) or none at all: Table I alone
    for absent in (compare.iloc[0:0], None):
        assert COMPARE_LABEL not in table1_markdown(precision_frame(), absent)


def test_report_markdown_has_every_table(bench_frame):
    t2, t3 = table2(bench_frame), table3(bench_frame)
    t4 = table4(pd.DataFrame(metrics_rows("guide_k10", [1.0])), [10])
    text = report_markdown(
        t2,
        t3,
        t4,
        precision_frame(),
        maps=["maze_0000", "maze_0001"],
        sweep_maps=["maze_0000"],
        protocol=Protocol(),
        params={"k_values": [10]},
        figure="trajectories.png",
    )
    for heading in ("## Table I", "## Table II", "## Table III", "## Table IV", "## Trajectories"):
        assert heading in text
    assert "maze_0000, maze_0001" in text and "sensor_range=20.0" in text and "k_values=[10]" in text
    assert "| 15 | 80.00 % | 75.92 % |" in text
    missing = report_markdown(t2, t3, None, None)
    assert "## Table I" in missing and "eval_predictor" in missing and "## Table IV" in missing


def test_the_team_table_has_a_row_per_planner_and_size_with_the_metrics_defined(bench_frame):
    row = {
        "label": "greedy_utility",
        "robots": 3,
        "episodes": 12,
        "makespan_mean_m": 200.04,
        "makespan_std_m": 20.5,
        "total_distance_mean_m": 580.0,
        "time_to_90_mean_m": 150.25,
        "makespan_over_single_distance": 0.4035,
        "completion_rate": 1.0,
    }
    text = team_table_markdown(
        {
            "greedy_utility@3": row,
            "greedy_utility@1": {**row, "robots": 1, "makespan_over_single_distance": 1.0, "completion_rate": 0.5},
        },
        "teams/team_coverage.png",
    )
    assert "| greedy_utility | 3 | 12 | 200.0 +- 20.5 | 580.0 | 150.2 | 0.40 | 100 % |" in text
    assert "| greedy_utility | 1 | 12 |" in text and "| 1.00 | 50 % |" in text
    assert "MARVEL" in text and "IR2" in text and "![team coverage](teams/team_coverage.png)" in text
    for none in (None, {}):
        assert "not run" in team_table_markdown(none).lower()
    assert "## Teams" in report_markdown(table2(bench_frame), table3(bench_frame), teams={"greedy_utility@3": row})


def test_metrics_json_is_flat_numbers(bench_frame):
    tables = {"table1": precision_frame(), "table2": table2(bench_frame), "table3": table3(bench_frame)}
    metrics = metrics_json(tables)
    json.dumps(metrics, allow_nan=False)
    assert metrics["table2"]["guide"]["gap_to_optimal"] == pytest.approx(0.15)
    assert metrics["table1"]["step15"]["precision"] == 0.8
    assert metrics["table3"]["dare"] == {"episodes": 0}  # not run; the paper's constants stay out
    assert metrics["table2"]["guide"]["episodes"] == 2 and isinstance(metrics["table2"]["guide"]["episodes"], int)
    assert not any(key.startswith("paper_") for rows in metrics.values() for row in rows.values() for key in row)


def test_log_tables_to_mlflow_one_experiment_per_table(bench_frame, mlflow_uri):
    import mlflow

    sweep = pd.DataFrame(metrics_rows("guide_k10", [1.0]) + metrics_rows("guide_k30", [2.0]))
    tables = {
        "table1": precision_frame(),
        "table2": table2(bench_frame),
        "table3": table3(bench_frame),
        "table4": table4(sweep, [10, 30], planners=["guide"]),
    }
    run_ids = log_tables_to_mlflow(tables, tracking_uri=mlflow_uri, params={"maps": "test"})
    assert {name: len(ids) for name, ids in run_ids.items()} == {
        "table1_inference": 2,
        "table2_benchmark": 4,
        "table3_ablation": 4,
        "table4_denoising_steps": 2,
    }
    client = mlflow.MlflowClient(tracking_uri=mlflow_uri)
    runs = client.search_runs([client.get_experiment_by_name("table4_denoising_steps").experiment_id])
    by_name = {run.info.run_name: run for run in runs if run.info.run_id in run_ids["table4_denoising_steps"]}
    assert set(by_name) == {"guide_k10", "guide_k30"}
    assert by_name["guide_k30"].data.params == {"planner": "guide", "K": "30", "maps": "test"}
    assert by_name["guide_k30"].data.metrics["distance_mean_m"] == 2.0
    assert by_name["guide_k30"].data.metrics["paper_decision_s"] == 0.227
    guide = client.get_run(run_ids["table2_benchmark"][1])
    assert guide.info.run_name == "guide" and guide.data.metrics["gap_to_optimal"] == pytest.approx(0.15)
    assert guide.data.tags["paper_row"] == "GUIDE"


# --------------------------------------------------------------------------- figure and stage
def test_trajectory_figure_grid(small_maze_path, tmp_path):
    frame = pd.DataFrame(metrics_rows("a", [4.0]) + metrics_rows("b", [8.0]))
    frame["map"] = "small"
    write_trajectory_csv(tmp_path / "a" / "small.csv", [(0, 0), (4, 0)])
    write_trajectory_csv(tmp_path / "b" / "small.csv", [(0, 0), (4, 0), (4, 4)])
    path = trajectory_figure([small_maze_path], frame, tmp_path, ["b", "missing", "a"], tmp_path / "fig.png")
    assert path.is_file() and path.stat().st_size > 1000
    with pytest.raises(ValueError, match="no trajectories"):
        trajectory_figure([small_maze_path], frame, tmp_path, ["missing"], tmp_path / "none.png")


@pytest.fixture
def report_workspace(small_maze_path, tmp_path, monkeypatch, mlflow_uri):
    """A tmp working directory with params.yaml, one test maze and a hand-written benchmark."""
    (tmp_path / "data/mazes/test").mkdir(parents=True)
    shutil.copy(small_maze_path, tmp_path / "data/mazes/test/small.png")
    params = {
        "protocol": {"max_steps": 500},
        "report": {
            "k_values": [1, 2],
            "k_planners": ["nearest_frontier"],
            "k_option": "min_utility",
            "k_maps": 1,
            "ablation_planners": ["guide", "nearest_frontier"],
            "figure_planners": ["optimal", "nearest_frontier"],
            "workers": 1,
            "seed": 0,
        },
    }
    (tmp_path / "params.yaml").write_text(yaml.safe_dump(params))
    rows = metrics_rows("nearest_frontier", [40.0]) + metrics_rows("optimal", [32.0])
    for row in rows:
        row["map"] = "small"
    write_metrics_csv(tmp_path / "reports/benchmark/metrics.csv", rows)
    ground_truth, records = load_maze_png(small_maze_path), {}
    for planner, points in (("nearest_frontier", [(0, 0), (4, 0), (8, 0)]), ("optimal", [(0, 0), (0, 4)])):
        path = write_trajectory_csv(tmp_path / f"reports/benchmark/{planner}/small.csv", points)
        rows = replay(ground_truth, points, Protocol(max_steps=500), oracle=True).step_rows()
        write_steps_csv(steps_path(path), rows)
        records[(planner, "small")] = step_record(rows)
    planner_table(episode_table(records, SpeedModel(2.0)), SpeedModel(2.0)).to_csv(
        tmp_path / "reports/benchmark/exploration.csv", index=False
    )
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("MLFLOW_TRACKING_URI", mlflow_uri)
    return tmp_path


def test_report_stage_main(report_workspace):
    from stages import report as stage

    metrics = stage.main("params.yaml")
    root = report_workspace
    for name in ("table1", "table2", "table3", "table4", "table5"):
        assert (root / f"reports/tables/{name}.md").is_file()
    sweep = pd.read_csv(root / "reports/denoising_steps/metrics.csv")
    assert sorted(sweep["planner"]) == ["nearest_frontier_k1", "nearest_frontier_k2"]
    assert (root / "reports/denoising_steps/nearest_frontier_k2/small.csv").is_file()
    report = (root / "reports/report.md").read_text()
    for heading in ("## Table I", "## Table II", "## Table III", "## Table IV", "## Table V", "## Coverage curves"):
        assert heading in report
    assert "| nearest_frontier | 1 | " in report.split("## Table V")[1] and "| Scene 1 (64 x 85 m) | GUIDE |" in report
    assert (root / "reports/coverage.png").stat().st_size > 1000
    assert "| guide | GUIDE | not run |" in report
    assert "not run: reports/predictor/precision.csv is missing" in report
    assert "| nearest_frontier | 1 | 1 |" in report and "| nearest_frontier | 2 | 1 |" in report
    assert (root / "reports/trajectories.png").stat().st_size > 1000
    saved = json.loads((root / "reports/report.json").read_text())
    assert saved == metrics
    assert saved["table2"]["nearest_frontier"]["gap_to_optimal"] == pytest.approx(0.25)
    assert set(saved["table4"]) == {"nearest_frontier_k1", "nearest_frontier_k2"}
    assert set(saved["table5"]) == {"nearest_frontier", "optimal"}
    assert saved["table5"]["nearest_frontier"]["distance_m"] == pytest.approx(8.0)
    import mlflow

    runs = mlflow.search_runs(experiment_names=["table5_efficiency"])
    assert set(runs["tags.mlflow.runName"]) == {"nearest_frontier", "optimal"}
    assert "coverage.png" in {a.path for a in mlflow.artifacts.list_artifacts(run_id=runs["run_id"].iloc[0])}
    assert saved["table4"]["nearest_frontier_k1"]["completion_rate"] == 1.0


def test_report_stage_errors(report_workspace):
    from stages import report as stage

    params = yaml.safe_load((report_workspace / "params.yaml").read_text())
    params["report"]["k_option"] = "no_such_option"
    (report_workspace / "params.yaml").write_text(yaml.safe_dump(params))
    with pytest.raises(SystemExit, match="report.k_option"):
        stage.main("params.yaml")
    params["report"]["bogus"] = 1
    (report_workspace / "params.yaml").write_text(yaml.safe_dump(params))
    with pytest.raises(ValueError, match="bogus"):
        stage.main("params.yaml")
    (report_workspace / "reports/benchmark/metrics.csv").unlink()
    del params["report"]["bogus"]
    (report_workspace / "params.yaml").write_text(yaml.safe_dump(params))
    with pytest.raises(SystemExit, match="run the benchmark stage first"):
        stage.main("params.yaml")


def _files(folder) -> dict[str, bytes]:
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


def test_report_stage_folders_are_replaced_as_a_whole_or_not_at_all(report_workspace, monkeypatch):
    """reports/tables/ and reports/denoising_steps/: a failure halfway leaves each as the last run wrote it."""
    from pipeline.evaluation import benchmark as evaluation
    from pipeline.workflows import report as workflow
    from stages import report as stage

    root = report_workspace
    tables, sweep = root / "reports/tables", root / "reports/denoising_steps"
    stage.main("params.yaml")
    (tables / "table9.md").write_text("an earlier run's table")
    before = {folder: _files(folder) for folder in (tables, sweep)}

    def fails(*args, **kwargs):
        raise OSError("killed")

    real_table4, real_steps = workflow.table4_markdown, evaluation.write_steps_csv
    monkeypatch.setattr(workflow, "table4_markdown", fails)  # after table1, 2, 3 and 5 are written
    with pytest.raises(OSError, match="killed"):
        stage.main("params.yaml")
    assert _files(tables) == before[tables]
    monkeypatch.setattr(workflow, "table4_markdown", real_table4)
    before[sweep] = _files(sweep)  # the sweep, before the tables, was done and replaced as a whole

    episodes: list[str] = []

    def dies_on_the_second_episode(path, rows):
        if episodes:
            raise OSError("killed")
        episodes.append(str(path))
        return real_steps(path, rows)

    monkeypatch.setattr(evaluation, "write_steps_csv", dies_on_the_second_episode)
    with pytest.raises(OSError, match="killed"):
        stage.main("params.yaml")
    assert episodes and "denoising_steps.partial" in episodes[0]
    assert _files(sweep) == before[sweep] and _files(tables) == before[tables]
    monkeypatch.setattr(evaluation, "write_steps_csv", real_steps)

    stage.main("params.yaml")
    assert sorted(_files(tables)) == [f"table{k}.md" for k in (1, 2, 3, 4, 5)]
    assert sorted(_files(sweep)) == sorted(before[sweep])
    assert not [p for p in (root / "reports").rglob(".*")]
