"""Planner configs: every option of a planner, with its default, its check and one line of why.

Each registered planner has a frozen config dataclass of options beside it (as lerobot's
`configuration_x.py` sits beside `modeling_x.py`), a `config_dataclass` whose fields are typed
with `pipeline.common.config`'s constrained types (`whole`, `real`, `maybe(text(...))`, ...). The
same keys are the command line's `label=name:key=value`, `params.yaml`'s planner specs and
Python's `make_planner(name, key=value)`; `guide planners --options NAME` prints them. Values are
checked by pydantic when the config is made, before any model is loaded; a rule between options
is plain Python in `check` (run after the fields are validated). Python objects that are not
options (an injected inpainter or policy, a block model) go beside the config, as keyword
arguments of the planner (`objects`).
"""

from __future__ import annotations

import dataclasses
import types
import typing
import warnings
from dataclasses import dataclass
from typing import Annotated, Any, ClassVar, Literal, Union

from pipeline.common.config import Rule, config_dataclass

SPEC_KINDS = ("bool", "int", "float", "str")  # what a spec string's value can parse into


def option(default: Any, help: str) -> Any:
    """A config field: its default and one line saying what it is and why."""
    return dataclasses.field(default=default, metadata={"help": help})


@dataclass(frozen=True)
class OptionInfo:
    name: str
    default: Any
    kinds: frozenset[str] | None  # the spec kinds it takes; None: a Python object, set from Python only
    help: str


@config_dataclass
class PlannerConfig:
    """The options of one registered planner; subclasses add typed fields (checked by pydantic)
    and `check` the rules between them."""

    name: ClassVar[str] = ""  # the registered name (set by `register_planner`)
    description: ClassVar[str] = ""
    composition: ClassVar[str] = ""  # what the planner is built of, where it wraps others (one line)
    part: ClassVar[str] = ""  # the part of a planner the fields this class declares set ("" : the planner's own)
    uses_ground_truth: ClassVar[bool] = False  # an oracle: sees the ground truth (a reference or a bound)
    ignores_motion_rule: ClassVar[bool] = False  # moves through unobserved free space (the `optimal` reference only)
    needs_policy: ClassVar[bool] = False  # runs a trained diffusion policy (models/ or the shipped default)
    lattice_planner: ClassVar[bool] = True  # keeps the lattice graph (what the oracle bounds wrap)
    objects: ClassVar[tuple[str, ...]] = ()  # Python objects the planner takes beside its config
    # Old option name -> its new name: still taken for one release, with a one-line FutureWarning.
    renamed: ClassVar[dict[str, str]] = {}

    def __post_init__(self) -> None:
        self.check()

    def check(self) -> None:
        """ValueError naming the options for values that make no sense together (each value on its
        own is checked by its field's type, before this runs)."""

    def model_slots(self) -> dict[str, str]:
        """Option name -> model kind (`pipeline.models.defaults.MODEL_FILES`) of each trained model
        this planner loads with these options; an option left None takes the default model."""
        return {}

    @classmethod
    def options(cls) -> list[OptionInfo]:
        """Every option: name, default, the spec kinds it takes, help (those of the configs it
        extends first)."""
        hints = _field_annotations(cls)
        return [
            OptionInfo(f.name, f.default, option_kinds(hints.get(f.name, f.type)), f.metadata.get("help", ""))
            for f in dataclasses.fields(cls)
        ]

    @classmethod
    def option_parts(cls) -> list[tuple[str, list[OptionInfo]]]:
        """The options grouped by the part of the planner they set: the `part` of the config class
        that first declares each one (its base-most), "" for the planner's own; the paper's parts
        (those naming a section) first, then the planner's own, then the rest, each group in the
        order of its first option in `options`."""
        parts: dict[str, list[OptionInfo]] = {}
        for info in cls.options():
            parts.setdefault(_declared_part(cls, info.name), []).append(info)
        return sorted(parts.items(), key=lambda part: 0 if "Sec." in part[0] else 1 if not part[0] else 2)

    @classmethod
    def split(cls, options: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any], list[str]]:
        """(config fields, Python objects, unknown names) of keyword options (old names renamed)."""
        options = cls.rename_old_options(options)
        names = {f.name for f in dataclasses.fields(cls)}
        fields = {k: v for k, v in options.items() if k in names}
        objects = {k: v for k, v in options.items() if k in cls.objects}
        unknown = sorted(set(options) - names - set(cls.objects))
        return fields, objects, unknown

    @classmethod
    def rename_old_options(cls, options: dict[str, Any]) -> dict[str, Any]:
        """`options` with each old name of `renamed` replaced by its new one, warning once per name."""
        old = [name for name in cls.renamed if name in options]
        if not old:
            return options
        options = dict(options)
        for name in old:
            new = cls.renamed[name]
            if new in options:
                raise ValueError(f"{cls.name or cls.__name__}: give {new} only ({name} is its old name)")
            warnings.warn(
                f"{cls.name or cls.__name__}: option {name} is now {new}; {name} goes in the next release",
                FutureWarning,
                stacklevel=4,
            )
            options[new] = options.pop(name)
        return options

    def to_dict(self) -> dict[str, Any]:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}


def _declared_part(cls: type, name: str) -> str:
    """The `part` of the base-most class of `cls` that declares the field `name`."""
    for klass in reversed(cls.__mro__):
        if name in klass.__dict__.get("__annotations__", {}):
            return str(klass.__dict__.get("part", ""))
    return ""


def _field_annotations(cls: type) -> dict[str, Any]:
    """Each field's annotation as an object (`from __future__ import annotations` leaves strings)."""
    try:
        return typing.get_type_hints(cls, include_extras=True)
    except (NameError, TypeError):  # a name only a type checker sees: pydantic's resolved types instead
        return {name: info.annotation for name, info in getattr(cls, "__pydantic_fields__", {}).items()}


def option_kinds(annotation: Any) -> frozenset[str] | None:
    """The kinds ('bool', 'int', 'float', 'str') an option's annotation allows; None for an option
    that takes Python objects (a config object), which no spec sets.

    Constrained types are unwrapped (`Annotated`), so are `Optional` and unions (None is not a
    kind: a spec's null is checked by the config), and a `Literal` takes the kinds of its values
    (choices of strings: 'str')."""
    kinds = _kinds(annotation)
    return frozenset(kinds) if kinds and kinds <= set(SPEC_KINDS) else None


def _kinds(annotation: Any) -> set[str] | None:
    """The spec kinds of `annotation`; None where any part of it is not one (a Python object)."""
    if annotation is None or annotation is type(None):
        return set()
    if isinstance(annotation, Rule):  # a rule read alone: its constrained type
        return _kinds(annotation.type)
    origin = typing.get_origin(annotation)
    if origin is Annotated:
        return _kinds(typing.get_args(annotation)[0])
    if origin is Union or origin is types.UnionType:
        kinds: set[str] = set()
        for member in typing.get_args(annotation):
            inner = _kinds(member)
            if inner is None:
                return None
            kinds |= inner
        return kinds
    if origin is Literal:
        kinds = set()
        for value in typing.get_args(annotation):
            inner = _kinds(type(value))
            if inner is None:
                return None
            kinds |= inner
        return kinds
    if isinstance(annotation, type) and annotation.__name__ in SPEC_KINDS and annotation.__module__ == "builtins":
        return {annotation.__name__}
    return None
