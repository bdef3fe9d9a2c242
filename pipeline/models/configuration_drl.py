"""Configuration of the `drl` policy: an attention encoder over the observed graph with a pointer
over the robot's 5 x 5 lattice window (after Cao et al. 2024 and ARiADNE before it).

The encoder reads the observed graph the `dare` planner and the Gymnasium environment see
(`pipeline.prediction.observed_graph`): `max_nodes` nodes nearest the robot, each with the
features of `FEATURE_NAMES`, neighbour lists `max_neighbors` wide. Its keys are the `model`
mapping of params.yaml's `train_drl` section.
"""

from __future__ import annotations

from dataclasses import asdict
from typing import Annotated, Any

from pipeline.common.config import config_dataclass, positive, real, validate, whole


@config_dataclass
class DRLPolicyConfig:
    """Sizes of the attention-pointer policy and the observation it reads."""

    feature_dim: Annotated[int, whole(1)] = 7  # features per node (FEATURE_NAMES)
    max_nodes: Annotated[int, whole(1)] = (
        128  # nodes per observation, nearest the robot first (the environment's max_nodes)
    )
    max_neighbors: Annotated[int, whole(1)] = 25  # neighbour list width (the 5 x 5 window)
    d_model: Annotated[int, whole(1)] = 64  # width of the node embeddings
    heads: Annotated[int, whole(1)] = 4  # attention heads; must divide d_model
    encoder_layers: Annotated[int, whole(1)] = (
        4  # edge-masked self-attention layers: each widens a node's view by one graph hop
    )
    # Node spacings per unit of the dx, dy features (GlobalGraphConfig.position_scale_nodes).
    window_scale: Annotated[float, positive()] = 10.0
    logit_clip: Annotated[float, positive()] = (
        10.0  # pointer logits are logit_clip * tanh(score), as in the attention-model pointers
    )
    # Initial weight of the guidepost feature added to a slot's logit (learned; 0: none).
    guidepost_prior: Annotated[float, real(0.0)] = 3.0

    def __post_init__(self) -> None:
        if self.d_model % self.heads:
            raise ValueError(f"heads ({self.heads}) must divide d_model ({self.d_model})")

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None, root: str = "model") -> "DRLPolicyConfig":
        """Build from a dict (params.yaml's `train_drl.model`, an export); a refused value or an
        unknown key is a one-line ValueError naming it as `root.key`."""
        return validate(cls, values, root)
