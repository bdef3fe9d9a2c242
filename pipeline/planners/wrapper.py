"""A planner that wraps another: what our additions to a planner are built on.

A wrapper holds the planner it wraps (`inner`, given to its constructor) and changes what it
needs to. To the episode loop, the robot session and the recorders it is a `Planner`: each
attribute of that interface (`REPORTED`) is the wrapper's own once it sets one, else its inner
planner's, so that the outermost layer reports the decision of whichever layer made it. Nothing
else passes through: code that needs a layer's own state (the lattice graph of a graph planner,
the tour of the tour vote) asks for that layer (`innermost`, `layer`).
"""

from __future__ import annotations

import typing
from typing import TYPE_CHECKING, Any, TypeVar, cast

from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation, Planner, Waypoint
from pipeline.world.protocol import Protocol

P = TypeVar("P")

# The `Planner` interface's attributes a wrapper reports as its inner planner's until it sets its own.
REPORTED = (
    "name",
    "description",
    "needs_policy",
    "uses_ground_truth",
    "ignores_motion_rule",
    "prediction_trust",
    "trust_state",
    "decision_kind",
    "fallbacks",
    "last_decision",
)


class InnerUnlessSet:
    """A `Planner` attribute of a wrapper: its own value once set on it, else its inner planner's."""

    def __set_name__(self, owner: type, name: str) -> None:
        self.name = name

    def __get__(self, wrapper: Any, owner: type | None = None) -> Any:
        if wrapper is None:
            return self
        own = wrapper.__dict__
        return own[self.name] if self.name in own else getattr(own["inner"], self.name)

    def __set__(self, wrapper: Any, value: Any) -> None:
        wrapper.__dict__[self.name] = value


class TrustKeeping(typing.Protocol):
    """A planner that keeps a record of its checked predictions (`restore_trust`)."""

    def restore_trust(self, state: Any) -> None: ...


class PlannerWrapper(Planner):
    """`inner`, with what a subclass overrides; `reset`, `plan`, `check_protocol` and
    `restore_trust` go to it unless a subclass says otherwise."""

    if not TYPE_CHECKING:  # to a type checker each reads as the `Planner` attribute it reports
        name = InnerUnlessSet()
        description = InnerUnlessSet()
        needs_policy = InnerUnlessSet()
        uses_ground_truth = InnerUnlessSet()
        ignores_motion_rule = InnerUnlessSet()
        prediction_trust = InnerUnlessSet()
        trust_state = InnerUnlessSet()
        decision_kind = InnerUnlessSet()
        fallbacks = InnerUnlessSet()
        last_decision = InnerUnlessSet()

    def __init__(self, inner: Planner):
        self.inner = inner

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        self.inner.reset(frame, protocol, seed)

    def plan(self, observation: Observation) -> list[Waypoint]:
        return self.inner.plan(observation)

    def check_protocol(self, protocol: Protocol) -> None:
        self.inner.check_protocol(protocol)

    def restore_trust(self, state: Any) -> None:
        cast(TrustKeeping, self.inner).restore_trust(state)


def layers(planner: Planner) -> list[Planner]:
    """`planner` and every planner it wraps, outermost first."""
    chain = [planner]
    while isinstance(chain[-1], PlannerWrapper):
        chain.append(chain[-1].inner)
    return chain


def innermost(planner: Planner) -> Planner:
    """The planner every wrapper around `planner` holds in the end."""
    return layers(planner)[-1]


def layer(planner: Planner, kind: type[P]) -> P:
    """The outermost layer of `planner` that is a `kind` (a wrapper or the planner itself); a
    TypeError naming the layers when there is none."""
    for part in layers(planner):
        if isinstance(part, kind):
            return part
    names = " > ".join(type(part).__name__ for part in layers(planner))
    raise TypeError(f"{names}: no layer is a {kind.__name__}")
