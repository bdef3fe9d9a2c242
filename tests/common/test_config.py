"""The config vocabulary on pydantic: what each type accepts, and the one line a refusal makes."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest
from pydantic import model_validator

from pipeline.common.config import (
    Section,
    any_of,
    check_value,
    config_dataclass,
    flag,
    fraction,
    identifier,
    list_of,
    maybe,
    pair,
    positive,
    real,
    satisfies,
    text,
    validate,
    whole,
)
from pipeline.stage_runner import read_protocol, read_stage


def refusal(kind, values: dict) -> str:
    with pytest.raises(ValueError) as error:
        validate(kind, values, "s")
    return str(error.value)


@pytest.mark.parametrize(
    ("kind", "good", "bad"),
    [
        (whole(1), [1, 7, 10**9, np.int64(3)], [0, -1, 2.0, 2.5, True, "3", None, math.nan]),
        (whole(0, 3), [0, 3], [-1, 4]),
        (real(), [0, -2.5, 1e300], [math.nan, math.inf, -math.inf, True, "1", None]),
        (positive(), [1e-9, 3], [0, -1, math.inf]),
        (fraction(), [0, 0.5, 1], [-0.1, 1.01, math.nan]),
        (real(0.0, 1.0, low_open=True, high_open=True), [0.5], [0.0, 1.0]),
        (flag(), [True, False], [0, 1, "true", None]),
        (text(), ["a", "cpu"], ["", "  ", 3, None, ["a"]]),
        (text(("cpu", "cuda")), ["cpu"], ["tpu", "CPU", None]),
        (identifier(), ["num_inference_steps"], ["k-steps", "1x", 3]),
        (maybe(whole(1)), [None, 2], [0, "x"]),
        (list_of(whole(0)), [[0], [1, 2]], [[], [-1], "1", 1, {"a": 1}]),
        (list_of(whole(0), min_length=0), [[]], [None]),
        (pair(whole(1)), [[1, 1], [2, 5]], [[5, 2], [1], [1, 2, 3], [0, 2], "1,2"]),
        (any_of(whole(1), text(("auto",))), [2, "auto"], [0, "gpu"]),
    ],
)
def test_each_type_accepts_its_values_and_refuses_the_others(kind, good, bad):
    for value in good:
        check_value(kind, value, "s.k")
    for value in bad:
        with pytest.raises(ValueError) as error:
            check_value(kind, value, "s.k")
        message = str(error.value)
        assert message.startswith("s.k") and "\n" not in message and "got " in message, message
        if not isinstance(value, list) or not value:  # a list's bad item is named as itself (s.k[1])
            assert message.endswith(f"got {value!r}"), message


class Ppo(Section):
    lr: positive()
    steps: whole(1)


class Training(Section):
    ppo: Ppo
    sides: list_of(positive()) = [1.0]
    epochs: whole(1, note="epochs") = 1


def test_a_refusal_is_one_line_naming_the_dotted_key_what_it_must_be_and_the_value():
    assert refusal(Training, {"ppo": {"lr": math.nan, "steps": 1}}) == "s.ppo.lr: must be a finite number > 0, got nan"
    assert (
        refusal(Training, {"ppo": {"lr": 1, "steps": 1}, "epochs": True})
        == "s.epochs: must be a whole number >= 1 (epochs), got True"
    )
    assert (
        refusal(Training, {"ppo": {"lr": 1, "steps": 1}, "sides": [1.0, -2.0]})
        == "s.sides[1]: must be a finite number > 0, got -2.0"
    )
    assert "\n" not in refusal(Training, {"ppo": "text\nmore"})


def test_missing_and_unknown_keys_are_named_at_any_depth():
    assert refusal(Training, {"ppo": {"lr": 0.1}}) == "s.ppo.steps: missing (the params file names every setting)"
    assert (
        refusal(Training, {"ppo": {"lr": 0.1, "steps": 2, "lrr": 3}})
        == "s.ppo.lrr: unknown setting (known: lr, steps), got 3"
    )
    assert refusal(Training, {}) == "s.ppo: missing (the params file names every setting)"
    assert refusal(Training, {"ppo": [1]}) == "s.ppo: must be a mapping of Ppo settings, got [1]"
    assert refusal(Training, [1]) == "s: must be a mapping of Training settings, got [1]"
    validate(Training, {"ppo": {"lr": 1, "steps": 1}}, "s")  # the keys with defaults may be left out


def test_maybe_reports_a_problem_inside_its_value_where_it_is():
    steps = maybe(list_of(whole(1)), "no sweep")
    with pytest.raises(ValueError, match=r"^s\[1\]: must be a whole number >= 1, got 0$"):
        check_value(steps, [1, 0], "s")
    with pytest.raises(ValueError, match=r"^s: must be a non-empty list of a whole number >= 1, or null \(no sweep\)"):
        check_value(steps, 3, "s")


def test_satisfies_carries_the_callables_own_message():
    def registered(name):
        if name not in ("greedy", "tare"):
            raise KeyError(f"unknown planner {name!r}")

    planners = list_of(satisfies(registered, "a registered planner name", str))
    assert check_value(planners, ["tare"], "s.planners") == ["tare"]
    with pytest.raises(ValueError) as error:
        check_value(planners, ["tare", "foo"], "s.planners")
    assert str(error.value) == "s.planners[1]: must be a registered planner name (unknown planner 'foo'), got 'foo'"


@config_dataclass
class Widths:
    width: whole(1) = 8
    groups: whole(1) = 4

    def __post_init__(self) -> None:
        if self.width % self.groups:
            raise ValueError(f"groups ({self.groups}) must divide width ({self.width})")


class WithModel(Section):
    model: Widths

    @model_validator(mode="after")
    def _small(self) -> "WithModel":
        if self.model.width > 64:
            raise ValueError("model.width above 64 does not fit")
        return self


def test_a_config_dataclass_checks_its_fields_its_rules_and_unknown_keys_where_it_is_nested():
    for model in ({}, {"width": 16}, {"groups": 2}):
        validate(WithModel, {"model": model}, "s")
    assert refusal(WithModel, {"model": {"width": 0}}) == "s.model.width: must be a whole number >= 1, got 0"
    assert refusal(WithModel, {"model": {"depth": 3}}).startswith("s.model.depth: unknown setting")
    assert refusal(WithModel, {"model": {"width": 10}}) == "s.model: groups (4) must divide width (10)"
    assert refusal(WithModel, {"model": {"width": 128}}) == "s: model.width above 64 does not fit"
    assert refusal(Widths, {"depth": 3}) == "s.depth: unknown setting (known: width, groups), got 3"
    with pytest.raises(ValueError, match=r"^Widths: width: must be a whole number >= 1, got 0$"):
        Widths(width=0)  # made directly: one line too
    config = Widths(width=16)
    assert dataclasses.replace(config, groups=8) == Widths(16, 8)
    with pytest.raises(ValueError):
        dataclasses.replace(config, groups=0)
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.width = 3


def test_read_stage_names_the_file_and_read_protocol_checks_the_protocol(tmp_path):
    class Settings(Section):
        n: whole(1)

    path = tmp_path / "p.yaml"
    path.write_text("s: {n: 2}\nprotocol: {max_steps: 0}\n")
    settings = read_stage(path, "s", Settings)
    assert settings.n == 2 and settings.as_written() == {"n": 2}
    with pytest.raises(
        ValueError, match=r"^.*p.yaml: protocol.max_steps: must be a whole number >= 1 \(waypoints\), got 0$"
    ):
        read_protocol(path)
    path.write_text("s: {n: 0}\n")
    with pytest.raises(ValueError, match=r"^.*p.yaml: s.n: must be a whole number >= 1, got 0$"):
        read_stage(path, "s", Settings)
    assert read_protocol(path).max_steps == 500  # no protocol section: the maze benchmark's
    with pytest.raises(ValueError, match=r"missing the 't' section"):
        read_stage(path, "t", Settings)
    with pytest.raises(FileNotFoundError):
        read_stage(tmp_path / "none.yaml", "s", Settings)
