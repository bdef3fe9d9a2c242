"""The `drl` policy: edge-masked graph attention over the observed graph, a pointer over the
robot's 5 x 5 lattice window, and a value head (after Cao et al. 2024 and ARiADNE).

`DRLPolicy(features, node_mask, neighbors, robot)` returns the logits of the 25 window slots
(the action space of `guide/Explore-v0`, slot = (dy + 2) * 5 + (dx + 2)) and the state's value.
The encoder is `pipeline.models.modeling_diffusion`'s masked self-attention: each layer lets a
node attend to its known-graph neighbours, so `encoder_layers` layers see that many hops. The
robot's node then attends to every node (the global context); the pointer scores each window
slot's node against [robot, context], plus a learned weight times the node's guidepost feature
(on the shortest path to the nearest unvisited frontier node): initialised at
`guidepost_prior`, it starts training from a policy that mostly follows the guidepost, as
nearest-frontier exploration does, rather than from a random walk whose greedy form loops. A
slot with no known neighbour gets `MASKED_LOGIT`.
`predict_action(observation)` is the planner's and the trained agent's decision: the best slot
among those the action mask allows.

The weights are plain torch: the `drl` planner loads an export (`save_drl_policy`) without any
RL library; training wraps the same module in sb3-contrib's MaskablePPO (`pipeline.training.drl`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch
from torch import nn

from pipeline.models.configuration_drl import DRLPolicyConfig
from pipeline.models.exports import read_weights_file, write_weights_file
from pipeline.models.modeling_diffusion import MaskedSelfAttentionLayer, build_attention_mask
from pipeline.prediction.global_graph import FEATURE_NAMES

WINDOW_RADIUS = 2  # the lattice window's reach in node spacings: slots are its 5 x 5 offsets
WINDOW = 2 * WINDOW_RADIUS + 1
SLOTS = WINDOW * WINDOW
MASKED_LOGIT = -1e8  # the logit of a slot with no node (sb3-contrib masks with the same value)
DRL_FORMAT = "guide-drl-policy/1"  # the `format` key of a drl export
GUIDEPOST = FEATURE_NAMES.index("guidepost")


class DRLPolicy(nn.Module):
    """Observed graph -> (window-slot logits (B, 25), value (B,))."""

    def __init__(self, config: DRLPolicyConfig = DRLPolicyConfig()) -> None:
        super().__init__()
        self.config = config
        d = config.d_model
        self.embed = nn.Linear(config.feature_dim, d)
        self.layers = nn.ModuleList(
            MaskedSelfAttentionLayer(d, config.heads, 0.0) for _ in range(config.encoder_layers)
        )
        self.norm = nn.LayerNorm(d)
        self.context = nn.MultiheadAttention(d, config.heads, batch_first=True)
        self.query = nn.Linear(2 * d, d)
        self.key = nn.Linear(d, d)
        self.value_head = nn.Sequential(nn.Linear(2 * d, d), nn.GELU(), nn.Linear(d, 1))
        self.guidepost_weight = nn.Parameter(torch.tensor(float(config.guidepost_prior)))

    def slot_rows(
        self, features: torch.Tensor, node_mask: torch.Tensor, neighbors: torch.Tensor, robot: torch.Tensor
    ) -> torch.Tensor:
        """(B, 25) the row of the node at each window slot of the robot (the robot's own at the
        centre), -1 where the known graph has none. A neighbour's slot is its lattice offset
        from the robot's node, read from the dx, dy features."""
        batch = features.shape[0]
        rows = torch.arange(batch, device=features.device)
        listed = neighbors[rows, robot].long()  # (B, M) neighbour rows, -1 padded
        index = listed.clamp(min=0)
        present = (listed >= 0) & node_mask[rows[:, None], index]
        offsets = torch.round(
            (features[rows[:, None], index, 0:2] - features[rows, robot, 0:2][:, None]) * self.config.window_scale
        ).long()
        inside = present & (offsets.abs() <= WINDOW_RADIUS).all(-1)
        slot = (offsets[..., 1] + WINDOW_RADIUS) * WINDOW + offsets[..., 0] + WINDOW_RADIUS
        slot = torch.where(inside, slot, torch.full_like(slot, SLOTS))  # a spare column swallows the rest
        table = torch.full((batch, SLOTS + 1), -1, dtype=torch.long, device=features.device)
        table = table.scatter(1, slot, torch.where(inside, listed, torch.full_like(listed, -1)))
        table[:, SLOTS // 2] = robot
        return table[:, :SLOTS]

    def forward(
        self, features: torch.Tensor, node_mask: torch.Tensor, neighbors: torch.Tensor, robot: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """features (B, N, F), node_mask (B, N), neighbors (B, N, M) with -1 padding, robot (B,) rows
        -> (logits (B, 25), value (B,))."""
        if features.shape[-1] != self.config.feature_dim:
            raise ValueError(
                f"features must have {self.config.feature_dim} channels, got shape {tuple(features.shape)}"
            )
        features, node_mask, robot = features.float(), node_mask.bool(), robot.long()
        allowed = build_attention_mask(neighbors, node_mask)
        h = self.embed(features)
        for layer in self.layers:
            h = layer(h, allowed)
        h = self.norm(h)
        rows = torch.arange(h.shape[0], device=h.device)
        robot_h = h[rows, robot]
        context, _ = self.context(robot_h.unsqueeze(1), h, h, key_padding_mask=~node_mask, need_weights=False)
        state = torch.cat([robot_h, context.squeeze(1)], dim=-1)  # (B, 2d)
        slot_rows = self.slot_rows(features, node_mask, neighbors, robot)
        keys = self.key(h[rows[:, None], slot_rows.clamp(min=0)])  # (B, 25, d)
        score = torch.einsum("bd,bsd->bs", self.query(state), keys) / math.sqrt(self.config.d_model)
        guidepost = features[rows[:, None], slot_rows.clamp(min=0), GUIDEPOST]
        logits = self.config.logit_clip * torch.tanh(score) + self.guidepost_weight * guidepost
        logits = torch.where(slot_rows >= 0, logits, torch.full_like(logits, MASKED_LOGIT))
        return logits, self.value_head(state).squeeze(-1)

    @torch.no_grad()
    def predict_action(self, observation: Mapping[str, Any], action_mask: np.ndarray | None = None) -> int:
        """The slot to move to: the highest logit among the slots `action_mask` (default:
        observation["action_mask"]) allows. `observation` holds one unbatched observation of
        `guide/Explore-v0` (features, node_mask, neighbors, robot)."""

        def batched(key: str, dtype: torch.dtype) -> torch.Tensor:
            return torch.as_tensor(np.asarray(observation[key]), dtype=dtype).unsqueeze(0)

        logits, _ = self(
            batched("features", torch.float32),
            batched("node_mask", torch.bool),
            batched("neighbors", torch.long),
            batched("robot", torch.long),
        )
        mask = np.asarray(observation["action_mask"] if action_mask is None else action_mask, dtype=bool)
        if mask.shape != (SLOTS,) or not mask.any():
            raise ValueError(
                f"action_mask must be {SLOTS} flags with at least one set, got {mask.astype(int).tolist()}"
            )
        scores = logits[0].numpy().copy()
        scores[~mask] = -np.inf
        return int(np.argmax(scores))


def save_drl_policy(policy: DRLPolicy, path: str | Path, trained_on: dict[str, Any] | None = None) -> Path:
    """Write the export the `drl` planner loads: config, weights and what it was trained on."""
    payload = {
        "format": DRL_FORMAT,
        "config": policy.config.to_dict(),
        "state_dict": {k: v.detach().cpu() for k, v in policy.state_dict().items()},
        "trained_on": trained_on or {},
    }
    return write_weights_file(payload, path)


def load_drl_policy(path: str | Path) -> tuple[DRLPolicy, dict[str, Any]]:
    """(the policy in `path`, in eval mode; what it was trained on); a one-line error if the file
    is not a drl export."""
    payload = read_weights_file(path, "a drl policy export")
    if payload.get("format") != DRL_FORMAT:
        raise ValueError(f"{path}: not a drl policy export (format {payload.get('format')!r}, expected {DRL_FORMAT!r})")
    policy = DRLPolicy(DRLPolicyConfig.from_dict(payload["config"]))
    policy.load_state_dict(payload["state_dict"])
    return policy.eval(), dict(payload.get("trained_on") or {})
