"""Every planner's constructor refuses options that make no sense, naming the option, the
value and the valid range, and still builds with its defaults and with valid edge values."""

from __future__ import annotations

import math
import re

import pytest

from pipeline.planners import make_planner, planner_names
from pipeline.planners.wrapper import innermost

NAN, INF = math.nan, math.inf
LEARNED = ("guide", "guide_noregion", "dare")

# (planner, bad options, a fragment of the message)
BAD = [
    # GraphPlanner's min_utility, shared by every lattice-graph planner
    ("nearest_frontier", {"min_utility": 0}, "min_utility: must be a whole number >= 1, got 0"),
    ("greedy_utility", {"min_utility": -1}, "min_utility: must be a whole number >= 1, got -1"),
    ("greedy_utility", {"min_utility": 1.5}, "min_utility: must be a whole number >= 1, got 1.5"),
    # nbvp
    ("nbvp", {"lam": NAN}, "lam: must be a finite number >= 0, or null (2.5 / sensor range), got nan"),
    ("nbvp", {"lam": INF}, "lam: must be a finite number >= 0, or null (2.5 / sensor range), got inf"),
    ("nbvp", {"lam": -1.0}, "lam: must be a finite number >= 0, or null (2.5 / sensor range), got -1.0"),
    (
        "nbvp",
        {"gain_threshold": NAN},
        "gain_threshold: must be a number >= 0 (inf = always the frontier fallback), got nan",
    ),
    (
        "nbvp",
        {"gain_threshold": -1.0},
        "gain_threshold: must be a number >= 0 (inf = always the frontier fallback), got -1.0",
    ),
    (
        "nbvp",
        {"tree_size": 1},
        "tree_size: must be a whole number >= 2 (the robot's node and at least one more), got 1",
    ),
    ("nbvp", {"sample_radius_factor": 0.0}, "sample_radius_factor: must be a finite number > 0, got 0.0"),
    ("nbvp", {"sample_radius_factor": INF}, "sample_radius_factor: must be a finite number > 0, got inf"),
    ("nbvp", {"ray_stride": 0}, "ray_stride: must be a whole number >= 1, got 0"),
    ("nbvp", {"max_attempts_factor": 0}, "max_attempts_factor: must be a whole number >= 1, got 0"),
    ("nbvp", {"min_utility": 0}, "min_utility: must be a whole number >= 1, got 0"),
    # tare
    (
        "tare",
        {"horizon_radius": -1},
        "horizon_radius: must be a whole number >= 0 (0 = the robot's region only), got -1",
    ),
    ("tare", {"min_cover": 0}, "min_cover: must be a whole number >= 1, got 0"),
    (
        "tare",
        {"cover_range": -1.0},
        "cover_range: must be a finite number >= 0 (0 = off), or null (the utility range), got -1.0",
    ),
    (
        "tare",
        {"cover_range": NAN},
        "cover_range: must be a finite number >= 0 (0 = off), or null (the utility range), got nan",
    ),
    ("tare", {"exact_max": 0}, "exact_max: must be a whole number in 1..14, got 0"),
    ("tare", {"exact_max": 15}, "exact_max: must be a whole number in 1..14, got 15"),
    ("tare", {"max_moves": -1}, "max_moves: must be a whole number >= 0 (0 = no 2-opt / Or-opt moves), got -1"),
    ("tare", {"min_utility": 0}, "min_utility: must be a whole number >= 1, got 0"),
    # optimal
    ("optimal", {"restarts": 0}, "restarts: must be a whole number >= 1, got 0"),
    (
        "optimal",
        {"lns_iterations": -1},
        "lns_iterations: must be a whole number >= 0 (0 = no ruin-and-recreate rounds), got -1",
    ),
    ("optimal", {"time_limit_s": -1}, "time_limit_s: must be a finite number > 0, or null (no limit), got -1"),
    ("optimal", {"time_limit_s": 0}, "time_limit_s: must be a finite number > 0, or null (no limit), got 0"),
    ("optimal", {"time_limit_s": NAN}, "time_limit_s: must be a finite number > 0, or null (no limit), got nan"),
    ("optimal", {"time_limit_s": INF}, "time_limit_s: must be a finite number > 0, or null (no limit), got inf"),
    # expert
    ("expert", {"restarts": 0}, "restarts: must be a whole number >= 1, got 0"),
    (
        "expert",
        {"lns_iterations": -1},
        "lns_iterations: must be a whole number >= 0 (0 = no ruin-and-recreate rounds), got -1",
    ),
    (
        "expert",
        {"replan_restarts": -1},
        "replan_restarts: must be a whole number >= 0 (0 = only refine the previous tour), got -1",
    ),
    (
        "expert",
        {"replan_lns_iterations": -2},
        "replan_lns_iterations: must be a whole number >= 0 (0 = no ruin-and-recreate rounds), got -2",
    ),
    ("expert", {"time_limit_s": 0.0}, "time_limit_s: must be a finite number > 0, or null (no limit), got 0.0"),
    (
        "expert",
        {"replan_time_limit_s": -5.0},
        "replan_time_limit_s: must be a finite number > 0, or null (no limit), got -5.0",
    ),
    ("expert", {"min_utility": 0}, "min_utility: must be a whole number >= 1, got 0"),
    # guide_tsp
    ("guide_tsp", {"top_k": -1}, "top_k: must be a whole number >= 0 (0 = every cluster), got -1"),
    (
        "guide_tsp",
        {"spread": -0.5},
        "spread: must be a finite number >= 0 (0 = each useful node its own target), or null (2.5 node spacings), got -0.5",
    ),
    (
        "guide_tsp",
        {"spread": NAN},
        "spread: must be a finite number >= 0 (0 = each useful node its own target), or null (2.5 node spacings), got nan",
    ),
    ("guide_tsp", {"min_weight": -1.0}, "min_weight: must be a finite number >= 0 (0 = keep every cluster), got -1.0"),
    ("guide_tsp", {"min_weight": INF}, "min_weight: must be a finite number >= 0 (0 = keep every cluster), got inf"),
    ("guide_tsp", {"beta": NAN}, "beta: must be a finite number >= 0, got nan"),
    ("guide_tsp", {"beta": -1.0}, "beta: must be a finite number >= 0, got -1.0"),
    ("guide_tsp", {"first_k": 0}, "first_k: must be a whole number >= 1, got 0"),
    (
        "guide_tsp",
        {"hysteresis": -1.0},
        "hysteresis: must be a finite number >= 0 (0 = none), or null (2 node spacings), got -1.0",
    ),
    ("guide_tsp", {"exact_max": 15}, "exact_max: must be a whole number in 1..14, got 15"),
    ("guide_tsp", {"max_moves": -1}, "max_moves: must be a whole number >= 0 (0 = no 2-opt / Or-opt moves), got -1"),
    ("guide_tsp", {"threshold": 2}, "threshold: must be a number in [0, 1], got 2"),
    ("guide_tsp", {"threshold": NAN}, "threshold: must be a number in [0, 1], got nan"),
    (
        "guide_tsp",
        {"min_component": -1},
        "min_component: must be a whole number >= 0 (0 or 1 = keep every prediction), got -1",
    ),
    ("guide_tsp", {"min_utility": 0}, "min_utility: must be a whole number >= 1, got 0"),
    # mapex
    ("mapex", {"wall_margin": -1}, "wall_margin: must be a whole number >= 0 (0 = off), got -1"),
    ("mapex", {"threshold": -0.5}, "threshold: must be a number in [0, 1], got -0.5"),
    (
        "mapex",
        {"min_component": -1},
        "min_component: must be a whole number >= 0 (0 or 1 = keep every prediction), got -1",
    ),
    # guide (its own options, the tour's and the predictor's)
    ("guide", {"threshold": 2}, "threshold: must be a number in [0, 1], got 2"),
    (
        "guide",
        {"prior_weight": NAN},
        "prior_weight: must be a finite number >= 0 (0 = the policy does not vote), got nan",
    ),
    (
        "guide",
        {"prior_weight": -1.0},
        "prior_weight: must be a finite number >= 0 (0 = the policy does not vote), got -1.0",
    ),
    (
        "guide",
        {"prior_weight": INF},
        "prior_weight: must be a finite number >= 0 (0 = the policy does not vote), got inf",
    ),
    (
        "guide",
        {"num_inference_steps": 101},
        "num_inference_steps: must be a whole number in 1..100 (the policy's num_train_timesteps), got 101",
    ),
    (
        "guide",
        {"num_inference_steps": 0},
        "num_inference_steps: must be a whole number >= 1, or null (the policy's own), got 0",
    ),
    (
        "guide",
        {"num_inference_steps": 101, "sampler": "ddim"},
        "num_inference_steps: must be a whole number in 1..100 (the policy's num_train_timesteps), got 101",
    ),
    ("guide", {"action_steps": 0}, "action_steps: must be a whole number >= 1, or null (the policy's own), got 0"),
    ("guide", {"action_steps": 9}, "action_steps: must be a whole number in 1..8 (the policy's horizon), got 9"),
    ("guide", {"candidates": 0}, "candidates: must be a whole number >= 1, got 0"),
    ("guide", {"stall_steps": 0}, "stall_steps: must be a whole number >= 1, got 0"),
    ("guide", {"sampler": "euler"}, "sampler: must be one of 'ddpm', 'ddim', or null (the policy's own), got 'euler'"),
    ("guide", {"mode": "greedy"}, "mode: must be one of 'tour', 'policy', got 'greedy'"),
    ("guide", {"top_k": -1}, "top_k: must be a whole number >= 0 (0 = every cluster), got -1"),
    ("guide", {"beta": NAN}, "beta: must be a finite number >= 0, got nan"),
    ("guide", {"min_utility": 0}, "min_utility: must be a whole number >= 1, got 0"),
    # the sliver gate (GraphPlanner), where a planner offers it
    ("greedy_utility", {"sliver_gate": 1}, "sliver_gate: must be true or false, got 1"),
    ("greedy_utility", {"gate_file": "gate.json"}, "gate_file is given but the sliver gate is off"),
    (
        "greedy_utility",
        {"sliver_gate": True, "gate_file": "no/such/gate.json"},
        "sliver gate file no/such/gate.json does not exist",
    ),
    ("guide_tsp", {"sliver_gate": False, "gate_file": "gate.json"}, "gate_file is given but the sliver gate is off"),
    ("guide", {"gate_file": "no/such/gate.json"}, "sliver gate file no/such/gate.json does not exist"),
    # guide_noregion and dare share the diffusion planners' checks
    (
        "guide_noregion",
        {"num_inference_steps": 101},
        "num_inference_steps: must be a whole number in 1..100 (the policy's num_train_timesteps), got 101",
    ),
    (
        "guide_noregion",
        {"prior_weight": NAN},
        "prior_weight: must be a finite number >= 0 (0 = the policy does not vote), got nan",
    ),
    (
        "dare",
        {"num_inference_steps": 101},
        "num_inference_steps: must be a whole number in 1..100 (the policy's num_train_timesteps), got 101",
    ),
    ("dare", {"candidates": 0}, "candidates: must be a whole number >= 1, got 0"),
    ("drl", {"stall_steps": -1}, "stall_steps: must be a whole number >= 0 (0 = never hand over), got -1"),
    ("drl", {"policy_file": "no/such/policy.pt"}, "no/such/policy.pt"),
    ("dare", {"threshold": 1.5}, "threshold: must be a number in [0, 1], got 1.5"),
    # the oracle bounds check their own options and pass the rest to their base planner
    ("oracle_gate", {"min_gain": 0}, "min_gain: must be a whole number >= 1 (cells), got 0"),
    ("oracle_gate", {"veto": "yes"}, "veto: must be true or false, got 'yes'"),
    ("oracle_gate", {"veto": True, "sliver_gate": False}, "drop sliver_gate=false"),
    (
        "oracle_gate",
        {"base": "expert"},
        "base: must be a lattice planner that does not see the ground truth (expert sees the ground truth), got 'expert'",
    ),
    (
        "oracle_gate",
        {"base": "no_such_planner"},
        "base: must be a lattice planner that does not see the ground truth (unknown planner 'no_such_planner'",
    ),
    ("oracle_tail", {"handover_cells": -1}, "handover_cells: must be a whole number >= 0, got -1"),
    ("oracle_lookahead", {"k": 0}, "k: must be a whole number >= 1, got 0"),
    ("sampled_lookahead", {"k": 0}, "k: must be a whole number >= 1, got 0"),
    ("sampled_lookahead", {"samples": 0}, "samples: must be a whole number >= 1, got 0"),
    ("sampled_lookahead", {"horizon_m": -1.0}, "horizon_m: must be a finite number >= 0 (metres), got -1.0"),
    (
        "sampled_lookahead",
        {"switch_margin_m": -1.0},
        "switch_margin_m: must be a finite number >= 0 (metres), or null (off), got -1.0",
    ),
    ("sampled_lookahead", {"exit_weight": -1.0}, "exit_weight: must be a finite number >= 0, got -1.0"),
    ("sampled_lookahead", {"temperature": 0.0}, "temperature: must be a finite number > 0, got 0.0"),
    (
        "sampled_lookahead",
        {"block_model_file": "no/such/block_model.pt"},
        "file not found (expected a block model file)",
    ),
    ("oracle_tail", {"base": "guide_tsp", "threshold": 2}, "threshold: must be a number in [0, 1], got 2"),
]

# Valid values at the edge of each range: still accepted (and the defaults' behaviour is untouched).
GOOD = [
    ("nearest_frontier", {"min_utility": 1}),
    ("nbvp", {"lam": 0.0, "gain_threshold": 0.0}),
    ("nbvp", {"gain_threshold": INF}),  # always the nearest-frontier fallback (tests/planners/baselines/test_nbvp.py)
    ("nbvp", {"tree_size": 2, "ray_stride": 1, "max_attempts_factor": 1}),
    ("tare", {"horizon_radius": 0, "min_cover": 1, "cover_range": 0.0, "exact_max": 14, "max_moves": 0}),
    ("optimal", {"restarts": 1, "lns_iterations": 0, "time_limit_s": None}),
    ("optimal", {"time_limit_s": 0.5}),
    ("expert", {"replan_restarts": 0, "replan_lns_iterations": 0, "time_limit_s": None, "replan_time_limit_s": None}),
    ("guide_tsp", {"top_k": 0, "min_weight": 0.0, "beta": 0.0, "hysteresis": 0.0, "first_k": 1, "exact_max": 1}),
    ("guide_tsp", {"threshold": 0.0, "min_component": 0}),
    ("mapex", {"threshold": 1.0, "wall_margin": 0, "min_component": 1}),
    ("guide", {"num_inference_steps": 100, "action_steps": 8, "prior_weight": 0.0, "top_k": 0}),
    ("guide", {"num_inference_steps": 1, "action_steps": 1, "candidates": 1, "stall_steps": 1, "sampler": "ddim"}),
    ("guide_noregion", {"num_inference_steps": 100}),
    ("dare", {"num_inference_steps": 100, "mode": "policy"}),
    ("drl", {"stall_steps": 0}),
    ("oracle_gate", {"base": "guide_tsp", "min_gain": 1, "veto": True}),
    ("oracle_tail", {"base": "nearest_frontier", "handover_cells": 0}),
    ("oracle_lookahead", {"k": 2, "sliver_gate": False}),
    ("sampled_lookahead", {"k": 1, "samples": 1, "horizon_m": 0.0, "sliver_gate": False}),
]


def case_id(case) -> str:
    name, options = case[0], case[1]
    return f"{name}-" + "-".join(f"{k}={v}" for k, v in options.items())


@pytest.mark.parametrize("name,options,fragment", BAD, ids=[case_id(c) for c in BAD])
def test_bad_option_is_refused(name, options, fragment):
    with pytest.raises(ValueError, match=re.escape(fragment)):
        make_planner(name, **options)


def test_every_planner_has_bad_option_cases():
    assert set(planner_names()) <= {name for name, _, _ in BAD}


@pytest.mark.parametrize("name", planner_names())
def test_every_planner_builds_with_its_defaults(name):
    planner = make_planner(name)
    assert planner.name == name


def test_diffusion_defaults_come_from_the_policy():
    for name in LEARNED:
        planner = make_planner(name)
        config = innermost(planner).policy.config
        assert innermost(planner).num_inference_steps == config.num_inference_steps <= config.num_train_timesteps
        assert innermost(planner).action_steps == config.action_steps


@pytest.mark.parametrize("name,options", GOOD, ids=[case_id(c) for c in GOOD])
def test_valid_edge_values_are_accepted(name, options):
    make_planner(name, **options)


def test_spec_errors_reach_the_benchmark_before_any_episode():
    """`--planner label=name:key=value` goes through the constructor's checks (the CLI's one-line error)."""
    from pipeline.evaluation.benchmark import build_planner, resolve_planner_specs

    for spec, message in (
        ("o=optimal:restarts=0", "planner 'o': restarts: must be a whole number >= 1, got 0"),
        ("t=guide_tsp:threshold=2", "planner 't': threshold: must be a number in [0, 1], got 2"),
    ):
        (resolved,) = resolve_planner_specs([spec])  # names, labels and value kinds
        with pytest.raises(ValueError, match=re.escape(message)):
            build_planner(resolved)
