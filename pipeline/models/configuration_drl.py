"""Configuration of the `drl` policy: an attention encoder over the observed graph with a pointer
over the robot's 5 x 5 lattice window (after Cao et al. 2024 and ARiADNE before it).

The encoder reads the observed graph the `dare` planner and the Gymnasium environment see
(`pipeline.prediction.observed_graph`): `max_nodes` nodes nearest the robot, each with the
features of `FEATURE_NAMES`, neighbour lists `max_neighbors` wide. Its keys are the `model`
mapping of params.yaml's `train_drl` section.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from pipeline.common.params import dataclass_from_dict


@dataclass(frozen=True)
class DRLPolicyConfig:
    """Sizes of the attention-pointer policy and the observation it reads."""

    feature_dim: int = 7  # features per node (FEATURE_NAMES)
    max_nodes: int = 128  # nodes per observation, nearest the robot first (the environment's max_nodes)
    max_neighbors: int = 25  # neighbour list width (the 5 x 5 window)
    d_model: int = 64  # width of the node embeddings
    heads: int = 4  # attention heads; must divide d_model
    encoder_layers: int = 4  # edge-masked self-attention layers: each widens a node's view by one graph hop
    window_scale: float = 10.0  # node spacings per unit of the dx, dy features (GlobalGraphConfig.position_scale_nodes)
    logit_clip: float = 10.0  # pointer logits are logit_clip * tanh(score), as in the attention-model pointers
    guidepost_prior: float = 3.0  # initial weight of the guidepost feature added to a slot's logit (learned; 0: none)

    def __post_init__(self) -> None:
        for name in ("feature_dim", "max_nodes", "max_neighbors", "d_model", "heads", "encoder_layers"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"DRLPolicyConfig.{name} must be a whole number >= 1, got {value!r}")
        if self.d_model % self.heads:
            raise ValueError(f"DRLPolicyConfig.heads ({self.heads}) must divide d_model ({self.d_model})")
        prior = self.guidepost_prior
        if isinstance(prior, bool) or not isinstance(prior, (int, float)) or not prior >= 0 or prior == float("inf"):
            raise ValueError(f"DRLPolicyConfig.guidepost_prior must be a finite number >= 0, got {prior!r}")
        for name in ("window_scale", "logit_clip"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
                raise ValueError(f"DRLPolicyConfig.{name} must be a positive number, got {value!r}")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None) -> "DRLPolicyConfig":
        return dataclass_from_dict(cls, values, "drl policy config key(s)")
