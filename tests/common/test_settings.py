"""The declarative settings checks: what each accepts, and the one message a refusal makes."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import pytest

from pipeline.common.settings import (
    PROTOCOL,
    AllOf,
    AnyOf,
    Fields,
    Flag,
    ListOf,
    Maybe,
    Pair,
    Real,
    Satisfies,
    Text,
    Whole,
    check_settings,
    check_stage,
    config_mapping,
    fraction,
    keys_of,
    positive,
)
from pipeline.world.protocol import Protocol


def refusal(spec: Fields, section: dict) -> str:
    with pytest.raises(ValueError) as error:
        check_settings({"s": section}, "s", spec, "p.yaml")
    return str(error.value)


@pytest.mark.parametrize(("check", "good", "bad"), [
    (Whole(1), [1, 7, 10**9], [0, -1, 2.0, 2.5, True, "3", None, math.nan]),
    (Whole(0, 3), [0, 3], [-1, 4]),
    (Real(), [0, -2.5, 1e300], [math.nan, math.inf, -math.inf, True, "1", None]),
    (positive(), [1e-9, 3], [0, -1, math.inf]),
    (fraction(), [0, 0.5, 1], [-0.1, 1.01, math.nan]),
    (Real(0.0, 1.0, low_open=True, high_open=True), [0.5], [0.0, 1.0]),
    (Flag(), [True, False], [0, 1, "true", None]),
    (Text(), ["a", "cpu"], ["", "  ", 3, None, ["a"]]),
    (Text(("cpu", "cuda")), ["cpu"], ["tpu", "CPU"]),
    (Text(identifier=True), ["num_inference_steps"], ["k-steps", "1x"]),
    (Maybe(Whole(1)), [None, 2], [0, "x"]),
    (ListOf(Whole(0)), [[0], [1, 2]], [[], [-1], "1", 1, {"a": 1}]),
    (ListOf(Whole(0), min_length=0), [[]], [None]),
    (Pair(Whole(1)), [[1, 1], [2, 5]], [[5, 2], [1], [1, 2, 3], [0, 2], "1,2"]),
    (AnyOf((Whole(1), Text(("auto",)))), [2, "auto"], [0, "gpu"]),
])
def test_each_check_accepts_its_values_and_refuses_the_others(check, good, bad):
    spec = Fields({"k": check})
    for value in good:
        check_settings({"s": {"k": value}}, "s", spec, "p.yaml")
    for value in bad:
        message = refusal(spec, {"k": value})
        assert message.startswith("p.yaml: s.k") and message.count(": ") >= 2 and "got " in message, message
        if not isinstance(value, list) or not value:  # a list's bad item is named as itself (s.k[1])
            assert message.endswith(f"got {value!r}"), message


def test_a_refusal_is_one_line_naming_the_dotted_key_what_it_must_be_and_the_value():
    spec = Fields({"ppo": Fields({"lr": positive()})})
    assert refusal(spec, {"ppo": {"lr": math.nan}}) == "p.yaml: s.ppo.lr: must be a finite number > 0, got nan"
    assert refusal(Fields({"n": Whole(1, note="epochs")}), {"n": True}) == \
        "p.yaml: s.n: must be a whole number >= 1 (epochs), got True"
    message = refusal(Fields({"sides": ListOf(positive())}), {"sides": [1.0, -2.0]})
    assert message == "p.yaml: s.sides[1]: must be a finite number > 0, got -2.0"
    assert "\n" not in refusal(Fields({"m": Fields({"a": Whole(0)})}), {"m": "text\nmore"})


def test_missing_and_unknown_keys_are_named_at_any_depth():
    spec = Fields({"ppo": Fields({"lr": positive(), "steps": Whole(1)})})
    assert refusal(spec, {"ppo": {"lr": 0.1}}) == "p.yaml: s.ppo.steps: missing (the params file names every setting)"
    message = refusal(spec, {"ppo": {"lr": 0.1, "steps": 2, "lrr": 3}})
    assert message.startswith("p.yaml: s.ppo.lrr: unknown setting (known: lr, steps)")
    assert refusal(spec, {}) == "p.yaml: s.ppo: missing (the params file names every setting)"
    assert refusal(spec, {"ppo": [1]}).startswith("p.yaml: s.ppo: must be a mapping of settings (lr, steps), got [1]")
    optional = Fields({"a": Whole(0), "b": Whole(0)}, frozenset({"b"}))
    check_settings({"s": {"a": 1}}, "s", optional, "p.yaml")


def test_a_missing_section_is_named_unless_optional():
    spec = Fields({"a": Whole(0)})
    with pytest.raises(ValueError, match=r"^p.yaml: missing the 's' section$"):
        check_settings({}, "s", spec, "p.yaml")
    check_settings({}, "s", spec, "p.yaml", required=False)
    check_settings({"s": None}, "s", spec, "p.yaml", required=False)


def test_maybe_reports_a_problem_inside_its_value_where_it_is():
    spec = Fields({"steps": Maybe(ListOf(Whole(1)), "no sweep")})
    assert refusal(spec, {"steps": [1, 0]}) == "p.yaml: s.steps[1]: must be a whole number >= 1, got 0"
    assert refusal(spec, {"steps": 3}).startswith("p.yaml: s.steps: must be a non-empty list of a whole number >= 1, or null (no sweep)")


def test_satisfies_carries_the_callables_own_message():
    def registered(name):
        if name not in ("greedy", "tare"):
            raise KeyError(f"unknown planner {name!r}")

    spec = Fields({"planners": ListOf(Satisfies(registered, "a registered planner name"))})
    check_settings({"s": {"planners": ["tare"]}}, "s", spec, "p.yaml")
    assert refusal(spec, {"planners": ["tare", "foo"]}) == \
        "p.yaml: s.planners[1]: must be a registered planner name (unknown planner 'foo'), got 'foo'"


@dataclass(frozen=True)
class Widths:
    width: int = 8
    groups: int = 4

    def __post_init__(self) -> None:
        if self.width % self.groups:
            raise ValueError(f"groups must divide width {self.width}")

    @classmethod
    def from_dict(cls, values):
        return cls(**values)


def test_a_config_mapping_takes_any_subset_of_fields_and_the_configs_own_rules():
    spec = Fields({"model": config_mapping(Widths, {"width": Whole(1)})})
    for model in ({}, {"width": 16}, {"groups": 2}):
        check_settings({"s": {"model": model}}, "s", spec, "p.yaml")
    assert refusal(spec, {"model": {"width": 0}}) == "p.yaml: s.model.width: must be a whole number >= 1, got 0"
    assert refusal(spec, {"model": {"depth": 3}}).startswith("p.yaml: s.model.depth: unknown setting (known: width, groups)")
    assert refusal(spec, {"model": {"width": 10}}) == \
        "p.yaml: s.model: must be valid Widths fields (groups must divide width 10), got {'width': 10}"


def test_all_of_stops_at_the_first_refusal_and_keys_of_keeps_the_order():
    spec = Fields({"b": AllOf((Whole(0), Satisfies(lambda v: 1 / (v % 2), "odd"))), "a": Flag()})
    assert keys_of(spec) == ("b", "a")
    assert refusal(spec, {"b": -1, "a": True}).startswith("p.yaml: s.b: must be a whole number >= 0")


def test_the_protocol_spec_is_the_protocols_fields_each_with_its_default():
    assert set(PROTOCOL.keys) == {f.name for f in fields(Protocol)}
    check_settings({}, "protocol", PROTOCOL, "p.yaml", required=False)
    check_settings({"protocol": {}}, "protocol", PROTOCOL, "p.yaml")
    check_settings({"protocol": Protocol().to_dict()}, "protocol", PROTOCOL, "p.yaml")
    with pytest.raises(ValueError, match=r"^p.yaml: protocol.sensor_range: must be a finite number > 0 \(metres\), got inf$"):
        check_settings({"protocol": {"sensor_range": math.inf}}, "protocol", PROTOCOL, "p.yaml")


def test_check_stage_reads_the_file_and_checks_the_protocol_too(tmp_path):
    spec = Fields({"n": Whole(1)})
    path = tmp_path / "p.yaml"
    path.write_text("s: {n: 2}\nprotocol: {max_steps: 0}\n")
    check_stage(path, "s", spec, protocol=False)
    with pytest.raises(ValueError, match=r"protocol.max_steps: must be a whole number >= 1"):
        check_stage(path, "s", spec)
    with pytest.raises(FileNotFoundError):
        check_stage(tmp_path / "none.yaml", "s", spec)
