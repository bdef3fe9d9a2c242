"""A planner that wraps another: what our additions to a planner are built on.

A wrapper holds the planner it wraps (`inner`) and changes what it needs to; everything else
reaches the inner planner. It is transparent: reading an attribute the wrapper does not have
reads the inner planner's (`graph`, `last_decision`, ...), and setting one the inner planner has
sets it there (an oracle bound swaps its base planner's gate, say). Wrappers nest: the
outermost reaches the innermost through each one.
"""

from __future__ import annotations

from typing import Any, ClassVar

from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation, Planner, Waypoint
from pipeline.world.protocol import Protocol


class PlannerWrapper(Planner):
    """`inner`, with what a subclass overrides; `reset`, `plan` and `check_protocol` pass through.

    A subclass names the attributes that are its own in `own`: those are always set on the
    wrapper, even where the inner planner has one of the same name.
    """

    own: ClassVar[frozenset[str]] = frozenset()

    def __init__(self, inner: Planner):
        object.__setattr__(self, "inner", inner)

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        self.inner.reset(frame, protocol, seed)

    def plan(self, observation: Observation) -> list[Waypoint]:
        return self.inner.plan(observation)

    def check_protocol(self, protocol: Protocol) -> None:
        self.inner.check_protocol(protocol)

    # The Planner attributes with class defaults are the inner planner's unless a wrapper sets its own.
    name = property(
        lambda self: self.__dict__.get("name", self.inner.name),
        lambda self, value: self.__dict__.__setitem__("name", value),
    )
    description = property(
        lambda self: self.__dict__.get("description", self.inner.description),
        lambda self, value: self.__dict__.__setitem__("description", value),
    )
    needs_policy = property(lambda self: self.inner.needs_policy)
    uses_ground_truth = property(lambda self: self.inner.uses_ground_truth)
    ignores_motion_rule = property(lambda self: self.inner.ignores_motion_rule)
    prediction_trust = property(lambda self: self.inner.prediction_trust)

    def __getattr__(self, attribute: str) -> Any:
        if attribute == "inner":  # not yet set: no recursion
            raise AttributeError(attribute)
        return getattr(self.inner, attribute)

    def __setattr__(self, attribute: str, value: Any) -> None:
        cls_attribute = getattr(type(self), attribute, None)
        if isinstance(cls_attribute, property):
            cls_attribute.__set__(self, value)
        elif attribute not in self.__dict__ and not self.owns(attribute) and hasattr(self.inner, attribute):
            setattr(self.inner, attribute, value)
        else:
            object.__setattr__(self, attribute, value)

    @classmethod
    def owns(cls, attribute: str) -> bool:
        return any(attribute in getattr(c, "own", ()) for c in cls.__mro__)


def innermost(planner: Planner) -> Planner:
    """The planner every wrapper around `planner` holds in the end."""
    while isinstance(planner, PlannerWrapper):
        planner = planner.inner
    return planner
