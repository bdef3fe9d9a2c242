"""Typed, validated configs on pydantic: one vocabulary for every setting the project reads.

A params.yaml section, a planner's options, a model's config, the protocol and the training
run's settings are all pydantic classes (a `Section` model or a `config_dataclass`) whose fields
are typed with the constrained types below. The library checks types, ranges, unknown and
missing keys, lists and nested mappings; these types only add the words: a refused value is one
error whose message says what the value must be,

    <dotted.key>: must be <what>, got <value!r>

which `explain` turns a `ValidationError` into (a missing or unknown key says so instead), and
the stage runner and the command line print as one `error:` line with exit status 2.

Two rules hold for every type here: a bool is never a number (YAML's `true` is a typo, not a
count), and NaN and infinities are never real numbers.

A field is annotated with its plain type, the rule beside it: `horizon: Annotated[int, whole(1)] = 8`.
The plain type is what a type checker reads; the rule (`Rule`) is what pydantic validates, and
it refuses, when the class is made, a plain type that is not its own.
"""

from __future__ import annotations

import dataclasses
import functools
import numbers
import types
import typing
from typing import Annotated, Any, Callable, Literal, Mapping, Optional, TypeVar, Union, dataclass_transform

import annotated_types as at
import pydantic
from pydantic import AllowInfNan, BaseModel, ConfigDict, Strict, ValidationError, WrapValidator, model_validator
from pydantic_core import ArgsKwargs, PydanticCustomError

__all__ = [
    "Rule",
    "Section",
    "ValidationError",
    "any_of",
    "check_value",
    "config_dataclass",
    "every_key",
    "explain",
    "fields_of",
    "flag",
    "fraction",
    "identifier",
    "list_of",
    "maybe",
    "pair",
    "positive",
    "real",
    "satisfies",
    "text",
    "validate",
    "whole",
]

T = TypeVar("T")
REFUSED = "refused"


class Rule:
    """A setting's constraints: the constrained type pydantic validates (`type`), written beside
    the field's plain type (`Annotated[int, whole(1)]`). Rules compose (`maybe(whole())`,
    `list_of(positive())`); `check_value` and the helpers take a rule where they take a type."""

    def __init__(self, constrained: Any):
        self.type = constrained

    def __get_pydantic_core_schema__(self, source: Any, handler: pydantic.GetCoreSchemaHandler) -> Any:
        if not _fits(_plain(source), _plain(self.type)):
            raise TypeError(f"a field annotated {source!r} has the rule of {_plain(self.type)!r}")
        return handler.generate_schema(self.type)

    def __repr__(self) -> str:
        return f"Rule({_what(self.type)!r})"


def _type(kind: Any) -> Any:
    """The constrained type of a rule; any other type as it is."""
    return kind.type if isinstance(kind, Rule) else kind


def _fits(plain: Any, rule: Any) -> bool:
    """Whether a field's plain type is its rule's: `Any` in a rule (a value a test parses into an
    object) takes any plain type there."""
    if rule is Any or plain == rule:
        return True
    if isinstance(plain, tuple) and isinstance(rule, tuple) and len(plain) == len(rule):
        return all(_fits(a, b) for a, b in zip(plain, rule))
    return False


def _plain(kind: Any) -> Any:
    """The plain type of a constrained one, as a type checker reads it: constraints dropped, a
    `Literal` of strings read as `str`, unions as sets of their members."""
    kind = _type(kind)
    origin = typing.get_origin(kind)
    if origin is Annotated:
        return _plain(typing.get_args(kind)[0])
    if origin is Union or origin is types.UnionType:
        members = frozenset(_plain(member) for member in typing.get_args(kind))
        return next(iter(members)) if len(members) == 1 else members
    if origin is Literal:
        kinds = {type(value) for value in typing.get_args(kind)}
        return kinds.pop() if len(kinds) == 1 else frozenset(kinds)
    if origin is not None:
        return (origin, *(_plain(arg) for arg in typing.get_args(kind)))
    return kind


def _refusing(what: str, deeper: bool = True) -> WrapValidator:
    """A wrapper that says `what` a value must be when the type underneath refuses it; with
    `deeper`, a refusal inside the value (an item of a list, a key of a mapping) keeps its own,
    deeper message."""

    def validate(value: Any, handler: Callable[[Any], Any]) -> Any:
        try:
            return handler(value)
        except ValidationError as error:
            if deeper and any(detail["loc"] for detail in error.errors()):
                raise
            raise PydanticCustomError(REFUSED, "must be {what}", {"what": what}) from None
        except (ValueError, AssertionError) as error:  # a rule of the type's own validators
            raise PydanticCustomError(
                REFUSED, "must be {what} ({reason})", {"what": what, "reason": str(error)}
            ) from None

    validate.what = what  # type: ignore[attr-defined]  # what the types that hold this one say of it
    return WrapValidator(validate)


def _noted(rule: str, note: str) -> str:
    return rule + (f" ({note})" if note else "")


def whole(minimum: int | None = 0, maximum: int | None = None, note: str = "") -> Rule:
    """A whole number (an int, not a bool, not 3.0) in minimum..maximum (None: no bound on that side)."""
    if minimum is None:
        rule = "" if maximum is None else f"<= {maximum}"
    else:
        rule = f">= {minimum}" if maximum is None else f"in {minimum}..{maximum}"
    bounds = ([at.Ge(minimum)] if minimum is not None else []) + ([at.Le(maximum)] if maximum is not None else [])
    return Rule(
        Annotated[
            (
                int,
                Strict(),
                *bounds,
                _refusing(_noted(f"a whole number {rule}".rstrip(), note)),
                pydantic.BeforeValidator(_plain_int),
            )
        ]
    )


def _plain_int(value: Any) -> Any:
    """numpy's integers as Python ints (a count computed with numpy is still a count)."""
    return int(value) if isinstance(value, numbers.Integral) and not isinstance(value, bool) else value


def real(
    low: float | None = None,
    high: float | None = None,
    *,
    low_open: bool = False,
    high_open: bool = False,
    note: str = "",
) -> Rule:
    """A finite number (an int or a float, never a bool, NaN or +-inf) between `low` and `high`
    (closed ends unless `low_open` / `high_open`; None: unbounded on that side). Kept as a float."""
    if low is not None and high is not None:
        rule = f"a number in {'(' if low_open else '['}{low:g}, {high:g}{')' if high_open else ']'}"
    else:
        rule = "a finite number"
        if low is not None:
            rule += f" {'>' if low_open else '>='} {low:g}"
        if high is not None:
            rule += f" {'<' if high_open else '<='} {high:g}"
    bounds: list[Any] = []
    if low is not None:
        bounds.append(at.Gt(low) if low_open else at.Ge(low))
    if high is not None:
        bounds.append(at.Lt(high) if high_open else at.Le(high))
    return Rule(Annotated[(float, Strict(), AllowInfNan(False), *bounds, _refusing(_noted(rule, note)))])


def positive(note: str = "") -> Rule:
    """A finite number > 0 (a length, a rate, a learning rate)."""
    return real(0.0, low_open=True, note=note)


def fraction(note: str = "") -> Rule:
    """A finite number in [0, 1] (a share, a probability threshold)."""
    return real(0.0, 1.0, note=note)


def flag() -> Rule:
    """true or false (not 0 / 1, not "yes")."""
    return Rule(Annotated[bool, Strict(), _refusing("true or false")])


def text(choices: tuple[str, ...] = (), note: str = "") -> Rule:
    """A non-empty string; with `choices`, one of them."""
    if choices:
        return Rule(Annotated[Literal[choices], _refusing(_noted("one of " + ", ".join(map(repr, choices)), note))])
    return Rule(
        Annotated[
            str,
            Strict(),
            at.Predicate(lambda value: bool(value.strip())),
            _refusing(_noted("a non-empty string", note)),
        ]
    )


def identifier(note: str = "") -> Rule:
    """A Python identifier (letters, digits, '_'): a name that becomes a key or a file name."""
    return Rule(
        Annotated[
            str,
            Strict(),
            at.Predicate(str.isidentifier),
            _refusing(_noted("an identifier (letters, digits, '_')", note)),
        ]
    )


def maybe(inner: Any, meaning: str = "") -> Rule:
    """null (None), meaning `meaning`, or a value of type `inner`."""
    return Rule(Annotated[Optional[_type(inner)], _refusing(_noted(f"{_what(inner)}, or null", meaning))])


def list_of(item: Any, min_length: int = 1, description: str = "") -> Rule:
    """A list (a tuple from Python) of at least `min_length` items of type `item` (paths key[i])."""
    if not description:
        size = {0: "a list (maybe empty)", 1: "a non-empty list"}.get(
            min_length, f"a list of at least {min_length} items"
        )
        description = f"{size} of {_what(item)}"
    return Rule(Annotated[types.GenericAlias(list, _type(item)), at.MinLen(min_length), _refusing(description)])


def pair(item: Any) -> Rule:
    """An inclusive range [low, high]: two values of type `item`, low <= high."""
    return Rule(
        Annotated[
            types.GenericAlias(list, _type(item)),
            at.Len(2, 2),
            at.Predicate(lambda value: value[0] <= value[1]),
            _refusing(f"a range [low, high] of {_what(item)}, low <= high"),
        ]
    )


def any_of(*options: Any, description: str = "") -> Rule:
    """A value one of `options` takes (e.g. a number of devices or "auto"), tried left to right."""
    what = description or " or ".join(_what(option) for option in options)
    if len(options) == 1:
        return Rule(Annotated[_type(options[0]), _refusing(what, deeper=False)])
    return Rule(
        Annotated[
            Union[tuple(map(_type, options))], pydantic.Field(union_mode="left_to_right"), _refusing(what, deeper=False)
        ]
    )


def satisfies(test: Callable[[Any], Any], description: str, kind: Any = Any, parses: bool = False) -> Rule:
    """A value `test` takes without a ValueError, TypeError or KeyError (a registered planner's
    name, by the registry's own lookup); the refusal carries the test's own message. With
    `parses`, the value read is what `test` returns (a planner spec, parsed once)."""

    def check(value: Any) -> Any:
        try:
            parsed = test(value)
        except (ValueError, TypeError, KeyError) as error:
            reason = str(error.args[0]) if isinstance(error, KeyError) and error.args else str(error)
            raise PydanticCustomError(
                REFUSED, "must be {what} ({reason})", {"what": description, "reason": reason}
            ) from None
        return parsed if parses else value

    return Rule(Annotated[_type(kind), pydantic.AfterValidator(check)])


def every_key(kind: Any, optional: tuple[str, ...] = ()) -> Rule:
    """A config (a config dataclass or Section model) whose mapping must name every field but
    `optional`: a params section names every setting, so a default cannot drift from the file."""
    names = list(_field_types(kind))

    def complete(values: Any) -> Any:
        if isinstance(values, Mapping):
            for name in names:
                if name not in values and name not in optional:
                    raise PydanticCustomError("missing_key", "missing {key}", {"key": name})
        return values

    return Rule(Annotated[kind, pydantic.BeforeValidator(complete)])


def _what(kind: Any) -> str:
    """The words a constrained type says it must be ("a whole number >= 1"), for the types that
    hold others (a list of them, a null or one)."""
    kind = _type(kind)
    if typing.get_origin(kind) is Annotated:
        for meta in reversed(kind.__metadata__):
            if isinstance(meta, WrapValidator) and hasattr(meta.func, "what"):
                return meta.func.what
    if isinstance(kind, type) and issubclass(kind, BaseModel):
        return f"a mapping of {kind.__name__} settings"
    return getattr(kind, "__name__", str(kind))


class Section(BaseModel):
    """A mapping of settings with exactly these keys: a params.yaml section or a part of one.

    A field with a default may be left out (its default is the value read); any other missing
    key, and any key the class does not name, is refused by name. A stage passes the model on and
    its code reads typed attributes; `as_written` gives the values as the file held them, for what
    must not change with the parsing: a resumable run's fingerprint, a file that records them.
    """

    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=False)
    _written: dict[str, Any] = pydantic.PrivateAttr(default_factory=dict)

    def as_written(self, *keys: str) -> dict[str, Any]:
        """The settings `keys` (all when none) the file held, as it held them: no default added, no
        value converted (a whole number stays one where the model reads a float)."""
        return {key: self._written[key] for key in keys or self._written if key in self._written}

    def replaced(self, **changes: Any) -> "Section":
        """The settings with `changes` made, checked again (a command-line override)."""
        return type(self).model_validate({**self._written, **changes})

    @model_validator(mode="wrap")
    @classmethod
    def _keep_written(cls, values: Any, handler: Callable[[Any], Any]) -> Any:
        model = handler(values)
        if isinstance(values, Mapping) and isinstance(model, Section):
            model._written = dict(values)
        return model

    @model_validator(mode="before")
    @classmethod
    def _known_keys_only(cls, values: Any) -> Any:
        if isinstance(values, Mapping):
            for key in values:
                if key not in cls.model_fields:
                    raise PydanticCustomError(
                        "unknown_key",
                        "unknown setting {key!r} (known: {known})",
                        {"key": key, "known": ", ".join(cls.model_fields)},
                    )
        return values


def fields_of(config: type[Any]) -> dict[str, tuple[Any, Any]]:
    """The fields of a `config_dataclass` as `pydantic.create_model` takes them (type, field), so
    that a flat params section holding a config's fields beside others checks them by the
    config's own types, written once."""
    return {name: (info.annotation, info) for name, info in config.__pydantic_fields__.items()}


@dataclass_transform(frozen_default=True)
def config_dataclass(cls: type[T]) -> type[T]:
    """A frozen dataclass whose fields are validated when it is made (a planner's or a model's
    config): `dataclasses.fields`, `replace` and pickling work as on any dataclass, an unknown
    keyword is refused, and a refused value is a ValueError of one line, `Name: key: must be ...`."""
    made: Any = pydantic.dataclasses.dataclass(
        frozen=True, config=ConfigDict(extra="forbid", arbitrary_types_allowed=True)
    )(cls)
    validating_init = made.__init__

    @functools.wraps(validating_init)
    def __init__(self: Any, *args: Any, **kwargs: Any) -> None:
        try:
            validating_init(self, *args, **kwargs)
        except ValidationError as error:
            raise ValueError(f"{type(self).__name__}: {explain(error)}") from None

    made.__init__ = __init__
    return made


def _path(loc: tuple[Any, ...]) -> str:
    path = ""
    for part in loc:
        path += f"[{part}]" if isinstance(part, int) else (f".{part}" if path else str(part))
    return path


def _field_types(kind: Any) -> dict[str, Any]:
    """Field name -> annotation of a Section model or a config dataclass ({} for anything else)."""
    if isinstance(kind, type) and issubclass(kind, BaseModel):
        return {name: info.annotation for name, info in kind.model_fields.items()}
    if hasattr(kind, "__pydantic_fields__"):
        return {name: info.annotation for name, info in kind.__pydantic_fields__.items()}
    return {}


def _config_at(kind: Any, loc: tuple[Any, ...]) -> Any:
    """The Section model or config dataclass found at `loc` inside `kind` (None when there is none):
    through nested configs, null-or types and lists."""
    for part in loc:
        while typing.get_origin(kind) is Annotated:
            kind = kind.__origin__
        if typing.get_origin(kind) in (Union, getattr(types, "UnionType", Union)):
            kind = next((arg for arg in typing.get_args(kind) if arg is not type(None)), None)
        if isinstance(part, int) and typing.get_origin(kind) in (list, tuple):
            kind = typing.get_args(kind)[0]
            continue
        kind = _field_types(kind).get(part)
        if kind is None:
            return None
    while typing.get_origin(kind) is Annotated:
        kind = kind.__origin__
    if typing.get_origin(kind) in (Union, getattr(types, "UnionType", Union)):
        kind = next((arg for arg in typing.get_args(kind) if _field_types(arg)), None)
    return kind if _field_types(kind) else None


def explain(error: ValidationError, root: str = "", kind_checked: Any = None) -> str:
    """The first refusal of a ValidationError as one line: `root.key.sub: must be ..., got value`.
    With `kind_checked` (the type validated), an unknown key names the known ones at any depth and a
    value that is not a mapping names the settings it should hold."""
    detail = error.errors(include_url=False)[0]
    loc = tuple(detail["loc"])
    kind, message, value = detail["type"], detail["msg"], detail.get("input")
    if kind == "unknown_key":
        key = detail["ctx"]["key"]
        loc, value = loc + (key,), value.get(key) if isinstance(value, Mapping) else None
        owner = f"{detail['ctx']['planner']} has no such option; " if "planner" in detail["ctx"] else ""
        message = f"unknown setting ({owner}known: {detail['ctx']['known']})"
    elif kind in ("extra_forbidden", "unexpected_keyword_argument"):
        config = _config_at(kind_checked, loc[:-1])
        known = f" (known: {', '.join(_field_types(config))})" if config is not None else ""
        message = f"unknown setting{known}"
    elif kind == "missing_key":
        loc, value = loc + (detail["ctx"]["key"],), dataclasses.MISSING
        message = "missing (the params file names every setting)"
    elif kind in ("missing", "missing_argument"):
        message = "missing (the params file names every setting)" if root else "missing"
        value = dataclasses.MISSING
    elif kind in ("value_error", "assertion_error"):
        message = message.split(", ", 1)[1] if message.startswith(("Value error, ", "Assertion failed, ")) else message
        value = dataclasses.MISSING  # its message says what was wrong with which values
    elif kind in ("model_type", "dataclass_type", "model_attributes_type", "dict_type", "dataclass_args_type"):
        config = _config_at(kind_checked, loc)
        message = (
            f"must be a mapping of {config.__name__} settings"
            if config is not None
            else "must be a mapping of settings"
        )
    elif kind != REFUSED:
        message = message[:1].lower() + message[1:]
    if isinstance(value, ArgsKwargs):  # a dataclass's arguments as a whole: not a value to show
        value = dataclasses.MISSING
    path = _path(((root,) if root else ()) + loc)
    shown = "" if value is dataclasses.MISSING else f", got {value!r}"
    return f"{path}: {message}{shown}" if path else f"{message}{shown}"


def check_value(kind: Any, value: Any, path: str) -> Any:
    """`value` as type `kind` takes it (a command-line override of one setting), or a ValueError
    `path: must be ..., got ...`."""
    kind = _type(kind)
    try:
        return _adapter(kind).validate_python(value)
    except ValidationError as error:
        raise ValueError(explain(error, path, kind)) from None


def _adapter(kind: Any) -> pydantic.TypeAdapter:
    """A TypeAdapter for `kind`, made once per type (making one compiles its validator)."""
    try:
        return _ADAPTERS[kind]
    except KeyError:
        adapter = _ADAPTERS[kind] = pydantic.TypeAdapter(kind)
        return adapter
    except TypeError:  # a type that cannot be a key
        return pydantic.TypeAdapter(kind)


_ADAPTERS: dict[Any, pydantic.TypeAdapter] = {}


def validate(kind: type[T], values: Mapping[str, Any] | None, root: str = "") -> T:
    """`kind` made from a mapping (a Section model or a config dataclass); a refusal is a ValueError
    with `explain`'s one line."""
    try:
        if isinstance(kind, type) and issubclass(kind, BaseModel):
            return typing.cast(T, kind.model_validate({} if values is None else values))
        if values is not None and not isinstance(values, Mapping):
            raise ValueError(f"{root + ': ' if root else ''}must be a mapping of settings, got {values!r}")
        values = dict(values or {})
        known = [field.name for field in dataclasses.fields(typing.cast(Any, kind))]
        for key in values:
            if key not in known:
                raise ValueError(
                    f"{_path(((root,) if root else ()) + (key,))}: unknown setting "
                    f"(known: {', '.join(known)}), got {values[key]!r}"
                )
        return _adapter(kind).validate_python(values)
    except ValidationError as error:
        raise ValueError(explain(error, root, kind)) from None
