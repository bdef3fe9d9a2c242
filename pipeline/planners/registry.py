"""The registry of planner names: `register_planner` makes a class available under a name."""

from __future__ import annotations

from typing import Callable, TypeVar

from pipeline.world.planner import Planner

_REGISTRY: dict[str, type[Planner]] = {}
P = TypeVar("P", bound=type[Planner])


class UnknownPlannerError(KeyError, ValueError):
    """A planner name that is not registered. A KeyError (a failed lookup) and a ValueError (a bad
    setting, which the stages print as one `error:` line), printed as plain text rather than
    KeyError's quoted repr."""

    def __str__(self) -> str:
        return str(self.args[0]) if self.args else "unknown planner"


def register_planner(name: str) -> Callable[[P], P]:
    """Class decorator: make a planner available under a lower-case `name`."""
    if not name.isidentifier() or name != name.lower():
        raise ValueError(f"planner names are lower-case identifiers, got {name!r}")

    def decorate(cls: P) -> P:
        if name in _REGISTRY and _REGISTRY[name] is not cls:
            raise ValueError(f"planner name {name!r} is already registered")
        cls.name = name
        _REGISTRY[name] = cls
        return cls

    return decorate


def planner_names() -> list[str]:
    """Every registered name (importing `pipeline.planners` registered the built-in ones)."""
    return sorted(_REGISTRY)


def planner_class(name: str) -> type[Planner]:
    names = planner_names()
    if name not in _REGISTRY:
        raise UnknownPlannerError(f"unknown planner {name!r}; choose from: {', '.join(names)}")
    return _REGISTRY[name]


def make_planner(name: str, **options) -> Planner:
    """A fresh planner instance by its registered name."""
    return planner_class(name)(**options)
