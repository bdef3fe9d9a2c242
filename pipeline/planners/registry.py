"""The registry of planner names: each name is a config class and what builds a planner from it.

`register_planner(name, Config)` decorates a planner class (built as `Planner(config, **objects)`)
or a function that builds one (`guide` picks the tour vote or the plain policy by its `mode`).
`make_planner(name, key=value, ...)` is how Python, the command line and `params.yaml` all build one.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable, TypeVar

from pipeline.common.config import validate
from pipeline.planners.config import OptionInfo, PlannerConfig
from pipeline.planners.matched_models import ProtocolMatchedModels, default_slots
from pipeline.planners.protocol_defaults import has_protocol_options
from pipeline.planners.whole_building import WholeBuilding
from pipeline.world.planner import Planner

Build = TypeVar("Build", bound=Callable[..., Planner])


@dataclass(frozen=True)
class PlannerEntry:
    name: str
    config: type[PlannerConfig]
    build: Callable[..., Planner]  # build(config, **objects) -> Planner


_REGISTRY: dict[str, PlannerEntry] = {}


class UnknownPlannerError(KeyError, ValueError):
    """A planner name that is not registered. A KeyError (a failed lookup) and a ValueError (a bad
    setting, which the stages print as one `error:` line), printed as plain text rather than
    KeyError's quoted repr."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "unknown planner"


def register_planner(name: str, config: type[PlannerConfig]) -> Callable[[Build], Build]:
    """Decorator: make a planner class (or a function that builds a planner) available under a
    lower-case `name`, configured by `config`."""
    if not name.isidentifier() or name != name.lower():
        raise ValueError(f"planner names are lower-case identifiers, got {name!r}")

    def decorate(build: Build) -> Build:
        entry = PlannerEntry(name, config, build)
        if name in _REGISTRY and _REGISTRY[name] != entry:
            raise ValueError(f"planner name {name!r} is already registered")
        if config.__dict__.get("name", name) != name:
            raise ValueError(
                f"{config.__name__} is registered as {config.name!r} already; give {name!r} its own config"
            )
        config.name = name  # the name its planner is known by (error messages say it)
        _REGISTRY[name] = entry
        return build

    return decorate


def planner_names() -> list[str]:
    """Every registered name (importing `pipeline.planners` registered the built-in ones)."""
    return sorted(_REGISTRY)


def planner_entry(name: str) -> PlannerEntry:
    if name not in _REGISTRY:
        raise UnknownPlannerError(f"unknown planner {name!r}; choose from: {', '.join(planner_names())}")
    return _REGISTRY[name]


def planner_config(name: str) -> type[PlannerConfig]:
    """The config class of a registered planner: its options, description and what it needs."""
    return planner_entry(name).config


def accepted_options(name: str, options: dict[str, Any] | None = None) -> dict[str, OptionInfo]:
    """The options a planner takes (for a wrapper, its base's too, by the `base` in `options`)."""
    config = planner_config(name)
    accepted = {info.name: info for info in config.options()}
    accepted.update({old: accepted[new] for old, new in config.renamed.items() if new in accepted})  # for one release
    accepted.update(
        {
            obj: OptionInfo(obj, None, None, "a Python object, set from Python")
            for obj in config.objects
            if obj != "base_options"
        }
    )
    base = getattr(config, "base_planner", None)
    if base is not None:
        base_name = base(options or {})
        if base_name in _REGISTRY:
            accepted = {**accepted, **{n: i for n, i in accepted_options(base_name).items() if n not in accepted}}
    return accepted


def make_config(name: str, **options: Any) -> tuple[PlannerConfig, dict[str, Any]]:
    """(the planner's config from `options`, the Python objects among them); ValueError for an
    option it does not take or a value its config refuses, in one line (`option: must be ..., got
    value`), never pydantic's multi-line ValidationError."""
    config, objects, _ = _config_and_fields(name, options)
    return config, objects


def _config_and_fields(name: str, options: dict[str, Any]) -> tuple[PlannerConfig, dict[str, Any], frozenset[str]]:
    """`make_config`'s pair and the names of the config fields `options` set."""
    config = planner_config(name)
    fields, objects, unknown = config.split(options)
    if unknown:
        settable = [
            n
            for n, info in accepted_options(name, options).items()
            if info.kinds is not None and n not in config.renamed
        ]
        raise ValueError(
            f"{name} has no option {', '.join(unknown)}; it accepts: {', '.join(settable) or 'no options'}"
        )
    return validate(config, fields), objects, frozenset(fields)


def make_planner(name: str, **options: Any) -> Planner:
    """A fresh planner by its registered name, with options as the command line and params.yaml give them.

    A planner with trained models left to the default (and no Python object injected), or with
    option defaults of its own at some protocol (`pipeline.planners.protocol_defaults`), comes
    wrapped in `ProtocolMatchedModels`, so that each reset takes the models trained at its protocol
    and the options it sets. Every planner but an oracle is wrapped in `WholeBuilding` (door nodes,
    the done rule on cells), which acts only under the door-aware graph.
    """
    config, objects, explicit = _config_and_fields(name, options)
    build = whole_building(planner_entry(name).build)
    if (default_slots(config) and not objects) or has_protocol_options(name):
        return ProtocolMatchedModels(config, build, name, explicit, objects)
    planner = build(config, **objects)
    planner.name = name
    return planner


def whole_building(build: Callable[..., Planner]) -> Callable[..., Planner]:
    """`build`, its planner wrapped in `WholeBuilding` unless it is an oracle (which sees the map)."""

    def build_whole(config: PlannerConfig, **objects: Any) -> Planner:
        planner = build(config, **objects)
        return planner if planner.uses_ground_truth else WholeBuilding(planner)

    return build_whole
