"""The registry of team planners, and how a name becomes one.

With `--robots N` a planner's own name means its coordinated team version where one is
registered here (`register_team_planner`); `uncoordinated_<name>` is every robot running its
own `<name>` blind to the others, for any single-robot planner; a single-robot name without a
team version runs uncoordinated too (what else could it do), and says so in its description.
Options are the single-robot planner's, plus the team version's own.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Callable

from pipeline.common.config import validate
from pipeline.planners.config import PlannerConfig
from pipeline.planners.registry import UnknownPlannerError, planner_config, planner_names
from pipeline.planners.team.uncoordinated import UncoordinatedTeam
from pipeline.world.team import TeamPlanner

UNCOORDINATED = "uncoordinated_"


@dataclass(frozen=True)
class TeamPlannerEntry:
    name: str
    config: type[PlannerConfig]
    build: Callable[..., TeamPlanner]  # build(config) -> TeamPlanner


_TEAM_REGISTRY: dict[str, TeamPlannerEntry] = {}


def register_team_planner(
    name: str, config: type[PlannerConfig]
) -> Callable[[Callable[..., TeamPlanner]], Callable[..., TeamPlanner]]:
    """Decorator: `name`'s coordinated team version, built as `build(config)`."""

    def decorate(build: Callable[..., TeamPlanner]) -> Callable[..., TeamPlanner]:
        entry = TeamPlannerEntry(name, config, build)
        if name in _TEAM_REGISTRY and _TEAM_REGISTRY[name] != entry:
            raise ValueError(f"team planner {name!r} is already registered")
        _TEAM_REGISTRY[name] = entry
        return build

    return decorate


def team_planner_names() -> list[str]:
    """The coordinated team versions, then `uncoordinated_<name>` of every single-robot planner."""
    return sorted(_TEAM_REGISTRY) + [UNCOORDINATED + n for n in planner_names()]


def is_coordinated(name: str) -> bool:
    return name in _TEAM_REGISTRY


def team_config(name: str) -> type[PlannerConfig]:
    """The config class a team name is checked against."""
    if name in _TEAM_REGISTRY:
        return _TEAM_REGISTRY[name].config
    return planner_config(name.removeprefix(UNCOORDINATED))


def make_team_planner(name: str, **options: Any) -> TeamPlanner:
    """A fresh team planner by name (see the module's doc), its options checked before anything is built."""
    if name in _TEAM_REGISTRY:
        entry = _TEAM_REGISTRY[name]
        planner = entry.build(validate(entry.config, options))
        planner.name = name
        return planner
    base = name.removeprefix(UNCOORDINATED)
    if base not in planner_names():
        raise UnknownPlannerError(f"unknown team planner {name!r}; choose from: {', '.join(team_planner_names())}")
    planner = UncoordinatedTeam(base, options)
    planner.name = name
    return planner
