"""A learned planner that takes, at each reset, the default models trained at the protocol it runs at.

A planner loads its models when it is made, before any protocol is known: the pipeline's
(models/), else the shipped maze-scale ones. Run at another scale (the real robot's 1 m lattice
and 10 m sensor), those models see inputs they were never trained on. This wrapper holds the
planner built as asked and, at each reset, picks every model the options leave to the default
for that protocol (`pipeline.models.defaults.pick_model`); when a pick differs from what the
planner holds, the planner is built again with the picks named. A model the options name is
never replaced, and a protocol no model matches keeps the first default, whose planner warns.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

from pipeline.models.defaults import pick_model
from pipeline.planners.config import PlannerConfig
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Observation, Planner, Waypoint
from pipeline.world.protocol import MODEL_INPUT_FIELDS, Protocol


def default_slots(config: PlannerConfig) -> dict[str, str]:
    """The model options of `config` left to the default (None): option name -> model kind."""
    return {name: kind for name, kind in config.model_slots().items() if getattr(config, name) is None}


class ProtocolMatchedModels(Planner):
    """`build(config)`, rebuilt at a reset whose protocol picks other default models.

    Transparent: reading or setting any other attribute reaches the held planner (an oracle
    bound swaps its base planner's gate after each reset, for one).
    """

    OWN = frozenset({"config", "build", "name", "slots", "inner", "picked", "_picks"})

    def __init__(self, config: PlannerConfig, build: Callable[[PlannerConfig], Planner], name: str):
        self.config, self.build, self.name = config, build, name
        self.slots = default_slots(config)
        self.inner = build(config)
        self.inner.name = name
        self.picked: dict[str, str | None] = {slot: None for slot in self.slots}  # None: the first default
        self._picks: dict[tuple[float, ...], dict[str, str | None]] = {}

    def picks_for(self, protocol: Protocol) -> dict[str, str | None]:
        """Option -> the model file that protocol picks (None where it is the first default anyway)."""
        key = tuple(float(getattr(protocol, field)) for field in MODEL_INPUT_FIELDS)
        if key not in self._picks:
            picks = {}
            for slot, kind in self.slots.items():
                path, first = pick_model(kind, protocol), pick_model(kind)
                picks[slot] = None if path is None or path == first else str(path)
            self._picks[key] = picks
        return self._picks[key]

    def use_models_for(self, protocol: Protocol) -> None:
        """Hold the planner built with the default models `protocol` picks."""
        picks = self.picks_for(protocol)
        if picks != self.picked:
            self.inner = self.build(replace(self.config, **{k: v for k, v in picks.items() if v is not None}))
            self.inner.name = self.name
            self.picked = picks

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        self.use_models_for(protocol)
        self.inner.reset(frame, protocol, seed)

    def plan(self, observation: Observation) -> list[Waypoint]:
        return self.inner.plan(observation)

    def check_protocol(self, protocol: Protocol) -> None:
        """Take the models of `protocol` (so that `description` names them), then warn as the planner does."""
        self.use_models_for(protocol)
        self.inner.check_protocol(protocol)

    # The Planner attributes with class defaults are the held planner's, not the wrapper's.
    description = property(lambda self: self.inner.description)
    needs_policy = property(lambda self: self.inner.needs_policy)
    uses_ground_truth = property(lambda self: self.inner.uses_ground_truth)
    ignores_motion_rule = property(lambda self: self.inner.ignores_motion_rule)
    prediction_trust = property(lambda self: self.inner.prediction_trust)

    def __getattr__(self, attribute: str) -> Any:  # last_decision, graph, ...: the planner's own
        if attribute == "inner":  # not yet built: no recursion
            raise AttributeError(attribute)
        return getattr(self.inner, attribute)

    def __setattr__(self, attribute: str, value: Any) -> None:
        if attribute in self.OWN:
            object.__setattr__(self, attribute, value)
        else:
            setattr(self.inner, attribute, value)


def model_files(planner: Planner) -> list[str]:
    """Every trained model file `planner` runs (through any wrapper): its policy and inpainter
    (`trained_models`, as the protocol check sees them), then its sliver gate."""
    files = [str(path) for path, _ in getattr(planner, "trained_models", [])]
    gate = getattr(planner, "gate_path", None)
    return files + ([str(gate)] if gate is not None else [])
