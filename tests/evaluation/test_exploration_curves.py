"""Coverage curves and their metrics (pipeline/evaluation/exploration_curves.py), exact on hand-made
records, and what `guide benchmark` writes and logs from them."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from typer.testing import CliRunner

from pipeline.cli import app
from pipeline.evaluation.exploration_curves import (
    SpeedModel,
    coverage_auc,
    distance_to_share,
    episode_table,
    mean_curve,
    planner_table,
    share_at,
    step_record,
)
from pipeline.reporting.benchmark_markdown import exploration_markdown


def record(distances, shares, decisions=None, area=100.0):
    decisions = decisions if decisions is not None else [0.0] * len(distances)
    return step_record(
        {"step": k, "distance_m": d, "explored_m2": s * area, "explored_share": s, "decision_ms": t}
        for k, (d, s, t) in enumerate(zip(distances, shares, decisions))
    )


A = record([0, 4, 8, 12], [0.2, 0.5, 0.9, 1.0], [0.0, 1000.0, 0.0, 500.0])
B = record([0, 8, 16], [0.2, 0.6, 0.95])


def test_distance_to_share_is_the_first_waypoint_reaching_it():
    assert distance_to_share(A, 0.5) == 4 and distance_to_share(A, 0.51) == 8 and distance_to_share(A, 0.99) == 12
    assert math.isnan(distance_to_share(B, 0.99))


def test_coverage_auc_is_the_area_under_the_step_curve():
    # 0.2 on [0, 4), 0.5 on [4, 8), 0.9 on [8, 12), 1.0 on [12, 16): mean over 16 m.
    assert coverage_auc(A, 16.0) == pytest.approx((0.2 + 0.5 + 0.9 + 1.0) * 4 / 16)
    assert coverage_auc(A, 6.0) == pytest.approx((0.2 * 4 + 0.5 * 2) / 6)  # a horizon inside the episode
    assert coverage_auc(A, 0.0) == 1.0


def test_speed_model_adds_decisions_to_driving():
    np.testing.assert_allclose(SpeedModel(2.0).times(A), [0.0, 2.0 + 1.0, 4.0 + 1.0, 6.0 + 1.5])
    with_nan = record([0, 4], [0.1, 0.2], [np.nan, np.nan])
    np.testing.assert_allclose(SpeedModel(4.0).times(with_nan), [0.0, 1.0])
    for bad in (0, -1.0, float("nan"), True, "2"):
        with pytest.raises(ValueError, match="speed_mps"):
            SpeedModel(bad)


def test_share_at_holds_between_and_after_waypoints():
    np.testing.assert_allclose(share_at(A, np.array([0, 3.9, 4, 11, 100]), A["distance_m"]), [0.2, 0.2, 0.5, 0.9, 1.0])
    mean, std = mean_curve([A, B], np.array([0.0, 8.0, 20.0]))
    np.testing.assert_allclose(mean, [0.2, (0.9 + 0.6) / 2, (1.0 + 0.95) / 2])
    np.testing.assert_allclose(std, [0.0, 0.15, 0.025])


def test_tables_per_episode_and_per_planner():
    speed = SpeedModel(2.0)
    episodes = episode_table({("a", "m1"): A, ("b", "m1"): B, ("a", "m2"): B}, speed)
    row = episodes.set_index(["planner", "map"]).loc[("a", "m1")]
    assert row.distance_to_90_m == 8 and row.time_s == pytest.approx(7.5)
    assert row.efficiency_m2_per_m == pytest.approx(100.0 / 12) and row.efficiency_m2_per_s == pytest.approx(100 / 7.5)
    assert row.coverage_auc == pytest.approx(coverage_auc(A, 16.0))  # m1's horizon: b's 16 m
    planners = planner_table(episodes, speed).set_index("planner")
    assert planners.loc["a", "maps"] == 2 and planners.loc["a", "reached_99"] == 1
    assert planners.loc["a", "distance_to_99_m"] == 12  # the mean over the maps that reached it
    assert math.isnan(planners.loc["b", "distance_to_99_m"]) and planners.loc["b", "reached_99"] == 0
    text = exploration_markdown(planners.reset_index())
    assert "| b | 8.0 | 16.0 | — (0/1 maps) |" in text and "2 m/s" in text


def test_guide_benchmark_writes_curves_and_logs_them(generated_maze_dir, tmp_path, mlflow_uri):
    import mlflow

    out = tmp_path / "bench"
    result = CliRunner().invoke(
        app,
        [
            "benchmark",
            "--maps",
            str(generated_maze_dir),
            "--planner",
            "greedy_utility",
            "--planner",
            "nearest_frontier",
            "--out",
            str(out),
            "--workers",
            "1",
            "--tracking-uri",
            mlflow_uri,
            "--experiment",
            "curves",
            "--speed-mps",
            "1.5",
        ],
    )
    assert result.exit_code == 0, result.output
    assert "coverage AUC" in (out / "summary.md").read_text()
    exploration = pd.read_csv(out / "exploration.csv").set_index("planner")
    assert set(exploration.index) == {"greedy_utility", "nearest_frontier"}
    assert (exploration["maps"] == 3).all() and (exploration["speed_mps"] == 1.5).all()
    assert (exploration["distance_to_90_m"] < exploration["distance_m"]).all()
    assert (out / "coverage.png").stat().st_size > 5000
    assert len(list((out / "greedy_utility").glob("*.steps.csv"))) == 3
    mlflow.set_tracking_uri(mlflow_uri)
    runs = mlflow.search_runs(experiment_names=["curves"]).set_index("tags.mlflow.runName")
    assert runs.loc["greedy_utility", "metrics.distance_to_90_m"] == pytest.approx(
        exploration.loc["greedy_utility", "distance_to_90_m"]
    )
    assert runs.loc["nearest_frontier", "metrics.efficiency_m2_per_s"] > 0
    artifacts = mlflow.artifacts.list_artifacts(run_id=runs.loc["greedy_utility", "run_id"])
    assert {"coverage.png", "exploration.csv"} <= {a.path for a in artifacts}


def test_guide_benchmark_refuses_a_bad_speed(generated_maze_dir, tmp_path):
    result = CliRunner().invoke(
        app,
        [
            "benchmark",
            "--maps",
            str(generated_maze_dir),
            "--planner",
            "greedy_utility",
            "--out",
            str(tmp_path / "b"),
            "--no-mlflow",
            "--speed-mps",
            "0",
        ],
    )
    assert result.exit_code == 2 and "--speed-mps" in result.output and not (tmp_path / "b").exists()
