"""Planner configs are pydantic config dataclasses (`pipeline.common.config`): every option is
checked by its field's type, a refusal reaches users as one line naming the option, and the
spec kinds each option takes are read from its annotation."""

from __future__ import annotations

import dataclasses
import re
from typing import Literal, Optional, Union

import numpy as np
import pydantic
import pytest

from pipeline.common.config import flag, maybe, positive, real, text, whole
from pipeline.planners import make_planner, planner_config, planner_names
from pipeline.planners.config import PlannerConfig, option_kinds
from pipeline.planners.guide.configuration_guide import SAMPLERS
from pipeline.planners.registry import make_config
from pipeline.planners.specs import build_planner, resolve_planner_specs
from pipeline.planners.wrapper import innermost
from pipeline.prediction.global_graph import GlobalGraphConfig


@pytest.mark.parametrize("name", planner_names())
def test_every_registered_config_is_a_pydantic_config_dataclass(name):
    config = planner_config(name)
    for cls in config.__mro__:
        if isinstance(cls, type) and issubclass(cls, PlannerConfig):
            assert pydantic.dataclasses.is_pydantic_dataclass(cls), cls
    made = config()
    assert dataclasses.is_dataclass(made)
    with pytest.raises(dataclasses.FrozenInstanceError):
        made.min_utility = 5  # frozen, whichever fields it has
    for info in config.options():  # the defaults are values the config takes
        if info.kinds is not None and info.default is not None:
            make_config(name, **{info.name: info.default})


@pytest.mark.parametrize(
    "spec, message",
    [
        ("g=greedy_utility:min_utility=-1", "planner 'g': min_utility: must be a whole number >= 1, got -1"),
        ("t=guide_tsp:exact_max=15", "planner 't': exact_max: must be a whole number in 1..14, got 15"),
        (
            "o=optimal:time_limit_s=0",
            "planner 'o': time_limit_s: must be a finite number > 0, or null (no limit), got 0",
        ),
        ("x=nbvp:reuse_best_branch=yes", "planner 'x': option reuse_best_branch='yes' must be true or false"),
        ("g=greedy_utility:gate_file=g.json", "planner 'g': gate_file is given but the sliver gate is off"),
        (
            "b=oracle_tail:base=expert",
            "planner 'b': base: must be a lattice planner that does not see the ground truth",
        ),
    ],
)
def test_a_bad_option_in_a_spec_is_one_line_naming_it(spec, message):
    with pytest.raises(ValueError) as error:
        build_planner(resolve_planner_specs([spec])[0])
    assert not isinstance(error.value, pydantic.ValidationError)
    assert "\n" not in str(error.value) and str(error.value).startswith(message), str(error.value)


def test_make_config_explains_and_whole_numbers_are_strict():
    with pytest.raises(ValueError, match=re.escape("first_k: must be a whole number >= 1, got 3.0")) as error:
        make_config("guide_tsp", first_k=3.0)  # a float is not a count, even a whole one
    assert not isinstance(error.value, pydantic.ValidationError)
    with pytest.raises(ValueError, match=re.escape("min_utility: must be a whole number >= 1, got True")):
        make_config("nearest_frontier", min_utility=True)
    config, objects = make_config("guide_tsp", first_k=np.int64(3), beta=2)  # numpy counts; ints for numbers
    assert config.first_k == 3 and type(config.first_k) is int
    assert config.beta == 2.0 and type(config.beta) is float and objects == {}


def test_a_direct_config_still_refuses_and_replace_checks_again():
    config = planner_config("tare")()
    with pytest.raises(ValueError, match="min_cover"):
        dataclasses.replace(config, min_cover=0)
    assert dataclasses.replace(config, min_cover=3).min_cover == 3


@pytest.mark.parametrize(
    "annotation, kinds",
    [
        (whole(1), {"int"}),
        (real(0.0), {"float"}),
        (positive(), {"float"}),
        (flag(), {"bool"}),
        (text(), {"str"}),
        (maybe(text(SAMPLERS)), {"str"}),
        (maybe(whole(1), "the policy's own"), {"int"}),
        (Optional[int], {"int"}),
        (int | float, {"int", "float"}),
        (Union[bool, str, None], {"bool", "str"}),
        (Literal["a", "b"], {"str"}),
        (Literal[True], {"bool"}),
        (GlobalGraphConfig, None),
        (pydantic.InstanceOf[GlobalGraphConfig], None),
        (dict[str, str], None),
        (Optional[GlobalGraphConfig], None),
    ],
)
def test_option_kinds_reads_the_annotation(annotation, kinds):
    assert option_kinds(annotation) == (None if kinds is None else frozenset(kinds))


def test_option_kinds_of_registered_options():
    kinds = {info.name: info.kinds for info in planner_config("guide").options()}
    assert kinds["sampler"] == {"str"} and kinds["mode"] == {"str"} and kinds["lookahead_targets"] == {"str"}
    assert kinds["num_inference_steps"] == {"int"} and kinds["lookahead"] == {"int"}
    assert kinds["threshold"] == {"float"} and kinds["count_threshold"] == {"float"} and kinds["spread"] == {"float"}
    assert kinds["lookahead_commit"] == {"bool"} and kinds["sliver_gate"] == {"bool"}
    assert kinds["policy_file"] == {"str"} and kinds["global_graph"] is None
    assert {info.name: info.kinds for info in planner_config("nbvp").options()}["gain_threshold"] == {"float"}


def test_an_injected_object_is_not_an_option():
    assert innermost(make_planner("greedy_utility", min_utility=1)).min_utility == 1
    with pytest.raises(ValueError, match="greedy_utility has no option policy"):
        make_config("greedy_utility", policy=object())
