"""Each planner's option defaults per protocol (`pipeline.planners.protocol_defaults`), taken at reset."""

from __future__ import annotations

from dataclasses import replace

import pytest

from pipeline.planners.matched_models import ProtocolMatchedModels
from pipeline.planners.protocol_defaults import PROTOCOL_OPTIONS, protocol_name, protocol_options
from pipeline.planners.registry import make_config, make_planner, planner_config
from pipeline.planners.wrapper import innermost
from pipeline.world.protocol import PAPER_REAL_ROBOT, PROTOCOLS, Protocol
from pipeline.world.simulator import run_episode


def test_every_table_names_a_protocol_and_options_its_planners_take():
    assert set(PROTOCOL_OPTIONS) == set(PROTOCOLS)
    for table in PROTOCOL_OPTIONS.values():
        for planner, options in table.items():
            config, _ = make_config(planner, **options)  # each value one its config accepts
            for option, value in options.items():
                assert getattr(config, option) == value
                assert value != getattr(planner_config(planner), option), f"{planner}.{option}: the config's own"


def test_a_protocol_takes_the_table_of_its_scale():
    assert protocol_name(Protocol()) == "maze"
    assert protocol_name(PAPER_REAL_ROBOT) == "real_robot"
    assert protocol_name(replace(PAPER_REAL_ROBOT, cell_size=0.05, max_steps=9)) == "real_robot"  # no model input
    assert protocol_name(Protocol(node_resolution=3.0)) == "maze"
    assert protocol_name(Protocol(cell_size=0.2, node_resolution=1.5)) == "real_robot"
    assert protocol_options("guide", Protocol())["spread"] is None
    assert protocol_options("guide", PAPER_REAL_ROBOT) == {} and protocol_options("greedy_utility", Protocol()) == {}
    with pytest.raises(ValueError, match="unknown protocol 'moon'; choose from: maze, real_robot"):
        protocol_options("guide", "moon")


def test_guide_takes_the_maze_defaults_at_the_maze_protocol_except_what_the_caller_set(small_maze):
    planner = make_planner("guide", candidates=2)
    assert isinstance(planner, ProtocolMatchedModels)
    assert innermost(planner).config.spread == 0.0  # built before any protocol: the config's
    result = run_episode(small_maze, planner, Protocol(), seed=0)
    assert result.complete
    held = innermost(planner).config
    assert (held.spread, held.min_weight, held.beta, held.exact_max, held.max_moves) == (None, 30.0, 1.5, 9, 200)
    assert planner.config.spread == 0.0  # the config as asked is kept: another protocol takes its own
    assert "[maze defaults: spread=null,min_weight=30.0,beta=1.5,exact_max=9,max_moves=200]" in planner.description
    planner.reset(small_maze, replace(PAPER_REAL_ROBOT, cell_size=Protocol().cell_size), 0)
    assert innermost(planner).config.spread == 0.0 and innermost(planner).config.beta == 0.0
    assert "defaults:" not in planner.description

    chosen = make_planner("guide_noregion", spread=0.0, beta=0.0, candidates=2)
    chosen.reset(small_maze, Protocol(), 0)
    assert (innermost(chosen).config.spread, innermost(chosen).config.beta, innermost(chosen).config.min_weight) == (
        0.0,
        0.0,
        30.0,
    )
