"""The headline metrics (`summarise` stage): a few named numbers from the report, Table I and the stage summaries."""

from __future__ import annotations

import json
import math

import pytest

from pipeline.reporting import headline as hl

TABLE2 = {  # report.json's table2 as metrics_json writes it: fractions, NaNs left out
    "optimal": {"distance_mean_m": 340.0, "gap_to_optimal": 0.0, "vs_baseline": -0.31, "vs_baseline_ci95": 0.075},
    "greedy_utility": {
        "distance_mean_m": 496.35125,
        "gap_to_optimal": 0.451488,
        "vs_baseline": 0.0,
        "vs_baseline_ci95": 0.0,
        "episodes": 12,
    },
    "guide": {
        "distance_mean_m": 483.93575,
        "gap_to_optimal": 0.415181,
        "vs_baseline": -0.025014,
        "vs_baseline_ci95": 0.094323,
        "decision_ms_median": 48.3,
    },
    "drl": {"distance_mean_m": 559.8, "vs_baseline": 0.127849},  # no gap, no half-width (NaN in the report)
}


def test_planner_metrics_are_named_for_reading_in_percent():
    planners = hl.planner_metrics(TABLE2)
    assert list(planners) == ["drl", "greedy_utility", "guide", "optimal"]
    assert planners["guide"] == {"distance_m": 483.9, "gap_pct": 41.5, "vs_greedy_pct": -2.5, "vs_greedy_ci95_pct": 9.4}
    assert planners["drl"] == {"distance_m": 559.8, "vs_greedy_pct": 12.8}


def test_the_reference_and_the_baseline_are_not_compared_with_themselves():
    planners = hl.planner_metrics(TABLE2)
    assert planners["optimal"] == {"distance_m": 340.0, "vs_greedy_pct": -31.0, "vs_greedy_ci95_pct": 7.5}
    assert planners["greedy_utility"] == {"distance_m": 496.4, "gap_pct": 45.1}


def test_non_finite_and_non_numeric_values_are_left_out():
    planners = hl.planner_metrics(
        {
            "a": {"distance_mean_m": float("nan"), "gap_to_optimal": "x", "vs_baseline": True},
            "b": {"distance_mean_m": 10},
        }
    )
    assert planners == {"b": {"distance_m": 10.0}}


def test_precision_by_step_reads_csv_rows_in_step_order():
    rows = [
        {"step": "30", "precision": "0.6966292134831461", "maps": "12"},
        {"step": "15", "precision": "0.7477477477477478"},
        {"step": "45", "precision": "nan"},
        {"step": "60", "precision": ""},
    ]
    assert hl.precision_by_step(rows) == {"step15": 0.748, "step30": 0.697}
    assert list(hl.precision_by_step(rows)) == ["step15", "step30"]


def test_stage_seconds_sums_the_summarys_top_level_times():
    summaries = {
        "fit_gate": {"seconds": 140.8, "auc_holdout": 0.97},
        "train_block_model": {
            "collect_seconds": 268.0,
            "train_seconds": 391.5,
            "history": [{"epoch": 1, "seconds": 196.7}],
        },  # nested epoch times are not added
        "train_drl": {"train_seconds": 140.5, "warm_start": {"seconds": 3.0}},
        "generate_mazes": {"mazes": 12},  # records no time: left out
        "broken": {"seconds": "soon", "flag_seconds": False},
    }
    seconds = hl.stage_seconds(summaries)
    assert seconds == {"fit_gate": 140.8, "train_block_model": 659.5, "train_drl": 140.5}
    assert list(seconds) == ["fit_gate", "train_block_model", "train_drl"]


def test_headline_is_json_with_planners_then_precision_then_seconds():
    metrics = hl.headline(TABLE2, [{"step": 15, "precision": 0.75}], {"collect_pairs": {"seconds": 60.9}})
    assert list(metrics) == ["drl", "greedy_utility", "guide", "optimal", "precision", "seconds"]
    assert metrics["precision"] == {"step15": 0.75} and metrics["seconds"] == {"collect_pairs": 60.9}
    values = [v for group in json.loads(json.dumps(metrics)).values() for v in group.values()]
    assert all(isinstance(v, float) and math.isfinite(v) for v in values)


def test_a_planner_label_that_clashes_with_a_group_is_refused():
    with pytest.raises(ValueError, match="seconds"):
        hl.headline({"seconds": {"distance_mean_m": 1.0}}, [], {})


def test_the_reference_and_baseline_names_match_the_report_stages():
    from pipeline.evaluation.benchmark import DEFAULT_BASELINE
    from pipeline.reporting.tables import PAIRED_BASELINE, REFERENCE_PLANNER

    assert hl.PAIRED_BASELINE == DEFAULT_BASELINE == PAIRED_BASELINE
    assert hl.REFERENCE_PLANNER == REFERENCE_PLANNER


def test_the_dagger_rounds_give_the_start_and_the_last_round():
    summary = {
        "seconds": 12.0,
        "rounds": [
            {"round": "start", "vs_greedy_pct": 15.02, "heldout_agreement": None},
            {"round": 0, "vs_greedy_pct": 9.5, "heldout_agreement": 0.41},
            {"round": 1, "vs_greedy_pct": 6.25, "heldout_agreement": 0.5},
        ],
    }
    metrics = hl.headline(TABLE2, [], {"distil_policy": summary})
    assert metrics["distil"] == {
        "rounds": 1.0,
        "start_vs_greedy_pct": 15.02,
        "policy_vs_greedy_pct": 6.25,
        "heldout_agreement": 0.5,
    }
    assert metrics["seconds"] == {"distil_policy": 12.0}
    assert "distil" not in hl.headline(TABLE2, [], {})
