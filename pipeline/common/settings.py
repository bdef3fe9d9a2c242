"""Declarative checks of a params file's settings, so that a bad value is one error naming its key.

Each stage declares the spec of its section beside its `KEYS`: a `Fields` mapping of key to
check (`Whole`, `Real`, `Flag`, `Text`, `Maybe`, `ListOf`, `Pair`, `Fields`, `AnyOf`,
`Satisfies`), and calls `check_settings` first thing in `main()`, before its workflow reads,
writes or deletes anything. A value a check refuses is a ValueError whose message is

    <file>: <dotted.key>: must be <what>, got <value!r>

(a missing or unknown key says so instead of "must be"), which the stage runner prints as one
`error:` line. The checks only say what a value may be; what a setting means stays with the
code that reads it. Booleans are never numbers here, and NaN and infinities are never real
numbers: YAML's `.nan` and `true` are typos, not counts.

This module is the bottom layer: checks that need the planner registry are `Satisfies` checks
that the stages build with a callable of their own.
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Mapping

from pipeline.common.params import load_params

__all__ = [
    "AllOf", "AnyOf", "Anything", "Check", "Fields", "Flag", "ListOf", "Maybe", "Pair", "PROTOCOL", "Real", "Refused",
    "Satisfies", "Text", "Whole", "check_protocol", "check_settings", "check_stage", "config_mapping", "fraction",
    "keys_of", "positive",
]


class Refused(Exception):
    """A value a check refuses: where (dotted key), what it must be, and the value itself."""

    def __init__(self, path: str, what: str, value: Any, *, shape: str = "must be {what}, got {value!r}") -> None:
        super().__init__(path, what, value)
        self.path, self.what, self.value, self.shape = path, what, value, shape

    def message(self) -> str:
        return f"{self.path}: " + self.shape.format(what=self.what, value=self.value)


class Check(ABC):
    """One rule for a value: `what` says it in words ("a whole number >= 1"), `check` refuses others."""

    what: str = "a value"

    @abstractmethod
    def check(self, value: Any, path: str) -> None: ...


class Predicate(Check):
    """A rule that looks at the value alone (`accepts`), not into its items."""

    def check(self, value: Any, path: str) -> None:
        if not self.accepts(value):
            raise Refused(path, self.what, value)

    @abstractmethod
    def accepts(self, value: Any) -> bool: ...


def is_number(value: Any) -> bool:
    """An int or float that is not a bool (YAML's true/false are not counts)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _bound(value: float) -> str:
    return f"{value:g}"


@dataclass(frozen=True)
class Whole(Predicate):
    """A whole number (an int, not a bool, not 3.0) in minimum..maximum (no upper bound when None)."""

    minimum: int = 0
    maximum: int | None = None
    note: str = ""

    @property
    def what(self) -> str:  # type: ignore[override]
        rule = f">= {self.minimum}" if self.maximum is None else f"in {self.minimum}..{self.maximum}"
        return f"a whole number {rule}" + (f" ({self.note})" if self.note else "")

    def accepts(self, value: Any) -> bool:
        return (isinstance(value, int) and not isinstance(value, bool) and value >= self.minimum
                and (self.maximum is None or value <= self.maximum))


@dataclass(frozen=True)
class Real(Predicate):
    """A finite number (int or float, not a bool, never NaN or +-inf) between `low` and `high`
    (closed ends unless `low_open` / `high_open`; None: unbounded on that side)."""

    low: float | None = None
    high: float | None = None
    low_open: bool = False
    high_open: bool = False
    note: str = ""

    @property
    def what(self) -> str:  # type: ignore[override]
        if self.low is not None and self.high is not None:
            rule = (f"a number in {'(' if self.low_open else '['}{_bound(self.low)}, "
                    f"{_bound(self.high)}{')' if self.high_open else ']'}")
        else:
            rule = "a finite number"
            if self.low is not None:
                rule += f" {'>' if self.low_open else '>='} {_bound(self.low)}"
            if self.high is not None:
                rule += f" {'<' if self.high_open else '<='} {_bound(self.high)}"
        return rule + (f" ({self.note})" if self.note else "")

    def accepts(self, value: Any) -> bool:
        if not is_number(value) or not math.isfinite(value):
            return False
        if self.low is not None and not (value > self.low if self.low_open else value >= self.low):
            return False
        return self.high is None or (value < self.high if self.high_open else value <= self.high)


def positive(note: str = "") -> Real:
    """A finite number > 0 (a length, a rate, a learning rate)."""
    return Real(0.0, low_open=True, note=note)


def fraction(note: str = "") -> Real:
    """A finite number in [0, 1] (a share, a probability threshold)."""
    return Real(0.0, 1.0, note=note)


@dataclass(frozen=True)
class Flag(Predicate):
    """true or false (not 0 / 1, not "yes")."""

    what: str = "true or false"

    def accepts(self, value: Any) -> bool:
        return isinstance(value, bool)


@dataclass(frozen=True)
class Text(Predicate):
    """A non-empty string; with `choices`, one of them; with `identifier`, a Python identifier."""

    choices: tuple[str, ...] = ()
    identifier: bool = False
    note: str = ""

    @property
    def what(self) -> str:  # type: ignore[override]
        if self.choices:
            rule = "one of " + ", ".join(repr(choice) for choice in self.choices)
        else:
            rule = "an identifier (letters, digits, '_')" if self.identifier else "a non-empty string"
        return rule + (f" ({self.note})" if self.note else "")

    def accepts(self, value: Any) -> bool:
        if not isinstance(value, str) or not value.strip():
            return False
        if self.choices:
            return value in self.choices
        return value.isidentifier() if self.identifier else True


@dataclass(frozen=True)
class Maybe(Check):
    """null (None), meaning `meaning`, or a value `inner` accepts."""

    inner: Check
    meaning: str = ""

    @property
    def what(self) -> str:  # type: ignore[override]
        return f"{self.inner.what}, or null" + (f" ({self.meaning})" if self.meaning else "")

    def check(self, value: Any, path: str) -> None:
        if value is None:
            return
        try:
            self.inner.check(value, path)
        except Refused as refused:
            if refused.path != path:  # a problem inside a nested value: say that one
                raise
            raise Refused(path, self.what, value) from None


@dataclass(frozen=True)
class AnyOf(Check):
    """A value one of `options` accepts (e.g. a number of devices or "auto")."""

    options: tuple[Check, ...]
    description: str = ""

    @property
    def what(self) -> str:  # type: ignore[override]
        return self.description or " or ".join(option.what for option in self.options)

    def check(self, value: Any, path: str) -> None:
        for option in self.options:
            try:
                option.check(value, path)
                return
            except Refused:
                continue
        raise Refused(path, self.what, value)


@dataclass(frozen=True)
class ListOf(Check):
    """A list of at least `min_length` items (1 unless told), each one `item` accepts (path key[i])."""

    item: Check
    min_length: int = 1
    description: str = ""

    @property
    def what(self) -> str:  # type: ignore[override]
        if self.description:
            return self.description
        size = "a non-empty list" if self.min_length == 1 else (
            "a list" if self.min_length == 0 else f"a list of at least {self.min_length} items")
        return f"{size} of {self.item.what}" if self.min_length else f"a list (maybe empty) of {self.item.what}"

    def check(self, value: Any, path: str) -> None:
        if not isinstance(value, list) or len(value) < self.min_length:
            raise Refused(path, self.what, value)
        for index, item in enumerate(value):
            self.item.check(item, f"{path}[{index}]")


@dataclass(frozen=True)
class Pair(Check):
    """An inclusive range [low, high]: a list of two values `item` accepts, low <= high."""

    item: Check

    @property
    def what(self) -> str:  # type: ignore[override]
        return f"a range [low, high] of {self.item.what}, low <= high"

    def check(self, value: Any, path: str) -> None:
        if not isinstance(value, list) or len(value) != 2:
            raise Refused(path, self.what, value)
        for index, item in enumerate(value):
            self.item.check(item, f"{path}[{index}]")
        if value[0] > value[1]:
            raise Refused(path, self.what, value)


@dataclass(frozen=True)
class Satisfies(Check):
    """A value `test` takes without a ValueError, TypeError or KeyError (e.g. a registered planner
    name, by the registry's own lookup); the refusal carries the test's own message."""

    test: Callable[[Any], Any]
    description: str

    @property
    def what(self) -> str:  # type: ignore[override]
        return self.description

    def check(self, value: Any, path: str) -> None:
        try:
            self.test(value)
        except (ValueError, TypeError, KeyError) as error:
            reason = str(error.args[0]) if isinstance(error, KeyError) and error.args else str(error)
            raise Refused(path, f"{self.description} ({reason})", value) from None


@dataclass(frozen=True)
class Anything(Predicate):
    """Any value: a key whose value another check judges (see `config_mapping`)."""

    what: str = "any value"

    def accepts(self, value: Any) -> bool:
        return True


@dataclass(frozen=True)
class AllOf(Check):
    """A value every one of `checks` accepts, tried in order (the first refusal is reported)."""

    checks: tuple[Check, ...]

    @property
    def what(self) -> str:  # type: ignore[override]
        return " and ".join(check.what for check in self.checks)

    def check(self, value: Any, path: str) -> None:
        for check in self.checks:
            check.check(value, path)


@dataclass(frozen=True)
class Fields(Check):
    """A mapping with exactly these keys, each value checked by its own check (paths key.sub).

    A key of `optional` may be left out (the code that reads the mapping has a default for it,
    e.g. a model config's dataclass field); any other missing key, and any key not in `keys`,
    is refused by name.
    """

    keys: Mapping[str, Check]
    optional: frozenset[str] = field(default_factory=frozenset)
    description: str = "a mapping of settings"

    @property
    def what(self) -> str:  # type: ignore[override]
        return self.description

    def check(self, value: Any, path: str) -> None:
        if not isinstance(value, dict):
            raise Refused(path, f"{self.description} ({', '.join(self.keys)})", value)
        where = f"{path}." if path else ""
        for key in value:
            if key not in self.keys:
                raise Refused(f"{where}{key}", ", ".join(self.keys), value[key],
                              shape="unknown setting (known: {what}), got {value!r}")
        for key, check in self.keys.items():
            if key in value:
                check.check(value[key], f"{where}{key}")
            elif key not in self.optional:
                raise Refused(f"{where}{key}", "", None, shape="missing (the params file names every setting)")


def config_mapping(config: type, checks: Mapping[str, Check], extra: Mapping[str, Check] | None = None) -> Check:
    """The mapping of a config dataclass with a `from_dict` (a model's `XConfig`).

    Every field may be left out (the config has a default for each: a profile names only those
    it changes); the fields in `checks` (those params.yaml sets) are checked here, the others by
    the config itself, and `extra` names keys its `from_dict` takes beside the fields. The config
    is built last, so that its rules across fields (heads divides d_model) are refused at the
    mapping's key too.
    """
    keys: dict[str, Check] = {f.name: checks.get(f.name, Anything()) for f in dataclasses.fields(config)}
    keys.update(checks)
    keys.update(extra or {})
    name = config.__name__
    return AllOf((Fields(keys, frozenset(keys), f"a mapping of {name} fields"),
                  Satisfies(config.from_dict, f"valid {name} fields")))


def check_settings(params: Mapping[str, Any], section: str, spec: Fields, path: str | Path,
                   *, required: bool = True) -> None:
    """Check `params[section]` against `spec`: a ValueError "<path>: <section.key>: ..." for the
    first value refused. A missing section is an error unless not `required` (the protocol,
    whose every value has a default)."""
    if section not in params or params[section] is None:
        if required:
            raise ValueError(f"{path}: missing the '{section}' section")
        return
    try:
        spec.check(params[section], section)
    except Refused as refused:
        raise ValueError(f"{path}: {refused.message()}") from None


def keys_of(spec: Fields) -> tuple[str, ...]:
    """The top-level keys a spec names, in its order (a stage's `KEYS`)."""
    return tuple(spec.keys)


# The shared `protocol` section (pipeline/world/protocol.py::Protocol; docs/protocol.md). Every
# value has the protocol's default, so each key, and the section itself, may be left out.
PROTOCOL_KEYS: dict[str, Check] = {
    "cell_size": positive("metres per grid cell"),
    "node_resolution": positive("lattice spacing in metres"),
    "sensor_range": positive("metres"),
    "utility_range": positive("metres"),
    "region_size": positive("metres"),
    "done_unknown_cells": Whole(0, note="cells"),
    "max_steps": Whole(1, note="waypoints"),
}
PROTOCOL = Fields(PROTOCOL_KEYS, frozenset(PROTOCOL_KEYS), "a mapping of protocol values")


def check_protocol(params: Mapping[str, Any], path: str | Path) -> None:
    """The shared `protocol` section against `PROTOCOL` (it may be absent: the defaults)."""
    check_settings(params, "protocol", PROTOCOL, path, required=False)


def check_stage(params_path: str | Path, section: str, spec: Fields, *, protocol: bool = True) -> None:
    """What a stage's `main()` calls first: the params file read (`load_params`: a missing file
    or bad YAML is its one-line error), its section checked against `spec`, then the protocol."""
    params = load_params(params_path)
    check_settings(params, section, spec, params_path)
    if protocol:
        check_protocol(params, params_path)
