"""A planner that takes, at each reset, the defaults of the protocol it runs at: its trained
models and its options.

A planner loads its models when it is made, before any protocol is known: the pipeline's
(models/), else the shipped maze-scale ones. Run at another scale (the real robot's 1 m lattice
and 10 m sensor), those models see inputs they were never trained on. This wrapper holds the
planner built as asked and, at each reset, picks every model the options leave to the default
for that protocol (`pipeline.models.defaults.pick_model`) and every option default that protocol
sets for it (`pipeline.planners.protocol_defaults`); when the picks differ from what the planner
holds, the planner is built again with them. A model or option the caller named is never
replaced, and a protocol no model matches keeps the first default, whose planner warns.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace
from typing import Any

from pipeline.models.defaults import pick_model
from pipeline.planners.config import PlannerConfig
from pipeline.planners.protocol_defaults import protocol_name, protocol_options
from pipeline.planners.wrapper import PlannerWrapper, innermost
from pipeline.world.maps import MapFrame
from pipeline.world.planner import Planner
from pipeline.world.protocol import MODEL_INPUT_FIELDS, Protocol


def default_slots(config: PlannerConfig) -> dict[str, str]:
    """The model options of `config` left to the default (None): option name -> model kind."""
    return {name: kind for name, kind in config.model_slots().items() if getattr(config, name) is None}


class ProtocolMatchedModels(PlannerWrapper):
    """`build(config, **objects)`, rebuilt at a reset whose protocol picks other default models or
    options. `explicit` names the options the caller set (never replaced); with Python objects
    injected (a model in memory) only the options are picked. The planner it holds (`inner`)
    changes at such a reset: ask for its layers (`pipeline.planners.wrapper.layer`) after it.
    """

    def __init__(
        self,
        config: PlannerConfig,
        build: Callable[..., Planner],
        name: str,
        explicit: frozenset[str] = frozenset(),
        objects: dict[str, Any] | None = None,
    ):
        super().__init__(build(config, **dict(objects or {})))
        self.config, self.build, self.name = config, build, name
        self.explicit, self.objects = frozenset(explicit), dict(objects or {})
        self.slots = {} if self.objects else default_slots(config)
        self.inner.name = name
        self.picked: dict[str, Any] = {}  # the options the held planner was built with beyond `config`
        self.protocol_defaults = ""  # the named protocol whose option defaults it holds ("": the config's)
        self._picks: dict[tuple[float, ...], dict[str, Any]] = {}

    def picks_for(self, protocol: Protocol) -> dict[str, Any]:
        """Option -> its value at that protocol, where it is not the config's: each model file that
        protocol picks (where not the first default anyway) and each option default it sets."""
        key = tuple(float(getattr(protocol, field)) for field in MODEL_INPUT_FIELDS)
        if key not in self._picks:
            picks = {}
            for slot, kind in self.slots.items():
                path, first = pick_model(kind, protocol), pick_model(kind)
                if path is not None and path != first:
                    picks[slot] = str(path)
            for option, value in protocol_options(self.name, protocol).items():
                if option not in self.explicit and getattr(self.config, option) != value:
                    picks[option] = value
            self._picks[key] = picks
        return self._picks[key]

    def use_models_for(self, protocol: Protocol) -> None:
        """Hold the planner built with the default models and options `protocol` picks."""
        picks = self.picks_for(protocol)
        if picks != self.picked:
            self.inner = self.build(replace(self.config, **picks), **self.objects)
            self.inner.name = self.name
            self.picked = picks
        options = sorted(set(picks) - set(self.slots))
        self.protocol_defaults = protocol_name(protocol) if options else ""

    def reset(self, frame: MapFrame, protocol: Protocol, seed: int) -> None:
        self.use_models_for(protocol)
        self.inner.reset(frame, protocol, seed)

    def check_protocol(self, protocol: Protocol) -> None:
        """Take the models of `protocol` (so that `description` names them), then warn as the planner does."""
        self.use_models_for(protocol)
        self.inner.check_protocol(protocol)

    @property
    def description(self) -> str:  # type: ignore[override]  # read-only: the held planner's, with the picks
        """The held planner's, naming the protocol's option defaults it was built with."""
        options = {k: v for k, v in self.picked.items() if k not in self.slots}
        if not options:
            return self.inner.description
        shown = ",".join(f"{k}={'null' if v is None else v}" for k, v in options.items())
        return f"{self.inner.description} [{self.protocol_defaults} defaults: {shown}]"


def model_files(planner: Planner) -> list[str]:
    """Every trained model file `planner` runs (through any wrapper): its policy and inpainter
    (`trained_models`, as the protocol check sees them), then its sliver gate."""
    base = innermost(planner)
    files = [str(path) for path, _ in getattr(base, "trained_models", [])]
    gate = getattr(base, "gate_path", None)
    return files + ([str(gate)] if gate is not None else [])
