"""The planner-spec language: `label=name:key=value,...`, as the command line, params.yaml and
Python (`make_planner(name, key=value)`) all name a planner variant.

"name" alone is a registered planner; "label=name" an alias; options after ':' are parsed as
int, float, bool or str and checked against the planner's config before anything is built.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from typing import Any, Sequence

from pipeline.planners.config import SPEC_KINDS, OptionInfo
from pipeline.planners.registry import accepted_options, make_planner, planner_config
from pipeline.world.planner import Planner

_LABEL = re.compile(r"^[A-Za-z0-9_][A-Za-z0-9_.\-]*$")  # a label names a folder and an MLflow run


@dataclass(frozen=True)
class PlannerSpec:
    """A registered planner under a label, built with keyword options (`make_planner(name, **options)`)."""

    label: str
    name: str
    options: dict[str, Any] = field(default_factory=dict, hash=False)

    @property
    def options_key(self) -> str:
        """The options as one canonical string (keys sorted): what tells two runs' variants apart."""
        return json.dumps(self.options, sort_keys=True, default=str)

    def __str__(self) -> str:
        if not self.options and self.label == self.name:
            return self.name
        text = f"{self.label}={self.name}"
        if self.options:
            text += ":" + ",".join(f"{key}={'null' if value is None else value}" for key, value in self.options.items())
        return text


def parse_option_value(text: str) -> Any:
    """'10' -> 10, '0.5' -> 0.5, 'true'/'false' (any case) -> bool, 'null' -> None (an option's default
    meaning, as in params.yaml), anything else stays a string."""
    lowered = text.lower()
    if lowered == "null":
        return None
    if lowered in ("true", "false"):
        return lowered == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def parse_planner_spec(text: str, reserved: Sequence[str] = ()) -> PlannerSpec:
    """Parse "name" or "label=name:key=value,key=value" (e.g. "guide_k10=guide:num_inference_steps=10").

    "label=name" without options is an alias. Values are parsed as int, float, bool or str.
    Only the syntax is checked here; `run_benchmark` checks that the name is registered
    and that the planner accepts the options. Raises ValueError naming the problem.
    """
    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"empty planner spec {text!r}; expected 'name' or 'label=name:key=value,...'")
    raw = text.strip()
    head, colon, tail = raw.partition(":")
    if "=" in head:
        label, _, name = (part.strip() for part in head.partition("="))
    elif colon:
        raise ValueError(f"planner spec {raw!r}: a planner with options needs a label, e.g. '{head.strip()}_v1={raw}'")
    else:
        label = name = head.strip()
    if not label or not _LABEL.match(label):
        raise ValueError(
            f"planner spec {raw!r}: label {label!r} must be letters, digits, '_', '-' or '.' (it names a folder)"
        )
    _check_label(raw, label, reserved)
    if not name or not name.isidentifier() or name != name.lower():
        raise ValueError(f"planner spec {raw!r}: planner name {name!r} must be a lower-case identifier")
    options: dict[str, Any] = {}
    if colon:
        if not tail.strip():
            raise ValueError(f"planner spec {raw!r}: nothing after ':'; expected key=value[,key=value]")
        for item in tail.split(","):
            key, equals, value = (part.strip() for part in item.partition("="))
            if not equals or not key or not value:
                raise ValueError(f"planner spec {raw!r}: option {item.strip()!r} is not key=value")
            if not key.isidentifier():
                raise ValueError(f"planner spec {raw!r}: option name {key!r} is not an identifier")
            if key in options:
                raise ValueError(f"planner spec {raw!r}: option {key!r} is given twice")
            options[key] = parse_option_value(value)
    return PlannerSpec(label, name, options)


def _check_label(raw: str, label: str, reserved: Sequence[str]) -> None:
    if label.lower() in reserved or label.lower().endswith(".tmp"):
        raise ValueError(f"planner spec {raw!r}: label {label!r} is the name of a benchmark output file; pick another")


def check_reserved(spec: PlannerSpec, reserved: Sequence[str]) -> PlannerSpec:
    """`spec`, or the parser's ValueError when its label is one of the `reserved` output file names."""
    _check_label(str(spec), spec.label, reserved)
    return spec


def as_specs(planners: Sequence[str | PlannerSpec]) -> list[PlannerSpec]:
    """Each entry as a PlannerSpec, a string parsed (`parse_planner_spec`): where a command line or a
    params file's planners enter, so that the spec is parsed once and carried from there."""
    return [entry if isinstance(entry, PlannerSpec) else parse_planner_spec(entry) for entry in planners]


def check_option_value(key: str, value: Any, info: OptionInfo) -> None:
    """ValueError when a spec's value is not of a kind the option's annotation allows."""
    kinds = info.kinds
    if kinds is None:
        raise ValueError(f"option {key!r} takes a Python object; set it from Python, not a spec")
    if value is None:
        return  # null: the config says whether this option may be null, and what null means
    kind = "bool" if isinstance(value, bool) else type(value).__name__
    if kind == "float" and not math.isfinite(value):
        raise ValueError(f"option {key}={value!r} must be a finite number")
    if kind in kinds or (kind == "int" and "float" in kinds):
        return
    wanted = {"bool": "true or false", "int": "an integer", "float": "a number", "str": "text"}
    expected = " or ".join(wanted[k] for k in SPEC_KINDS if k in kinds)
    raise ValueError(f"option {key}={value!r} must be {expected}")


def resolve_planner_specs(planners: Sequence[str | PlannerSpec], reserved: Sequence[str] = ()) -> list[PlannerSpec]:
    """Parse every entry, check the names are registered (KeyError listing the known ones),
    the options are the planner's config's with values of the right kind, and the labels are
    unique (ValueError). The values themselves are checked by the configs: `build_planner`."""
    specs = [
        check_reserved(entry, reserved) if isinstance(entry, PlannerSpec) else parse_planner_spec(entry, reserved)
        for entry in planners
    ]
    seen: set[str] = set()
    for spec in specs:
        planner_config(spec.name)  # unknown names fail here, with the list of known ones
        if spec.label in seen:
            raise ValueError(f"planner label {spec.label!r} is used twice; give each variant its own label")
        seen.add(spec.label)
        if not spec.options:
            continue
        accepted = accepted_options(spec.name, spec.options)
        unknown = sorted(set(spec.options) - set(accepted))
        if unknown:
            renamed = planner_config(spec.name).renamed  # old names: still taken, no longer listed
            settable = [name for name, info in accepted.items() if info.kinds is not None and name not in renamed]
            raise ValueError(
                f"planner {spec.label!r}: {spec.name} has no option {', '.join(unknown)}; "
                f"it accepts: {', '.join(settable) or 'no options'}"
            )
        try:
            for key, value in spec.options.items():
                check_option_value(key, value, accepted[key])
        except ValueError as error:
            raise ValueError(_option_error(spec, error)) from None
    return specs


def build_planner(spec: PlannerSpec) -> Planner:
    """The planner a resolved spec names; a value its constructor refuses is a one-line ValueError
    naming the label."""
    try:
        return make_planner(spec.name, **spec.options)
    except (TypeError, ValueError) as error:
        raise ValueError(_option_error(spec, error)) from None


def _option_error(spec: PlannerSpec, error: Exception) -> str:
    message = f"planner {spec.label!r}: {error}"
    if any(isinstance(v, str) and ":" in v and "=" in v for v in spec.options.values()):
        message += " (options are separated by ',', e.g. 'label=name:a=1,b=2')"
    return message
