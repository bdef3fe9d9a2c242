"""The GUIDE/DARE diffusion policy: a graph encoder and a noise-prediction network.

Observation: a padded graph of N nodes (features (N, F), validity mask (N,), neighbour lists
(N, M) padded with -1) and the robot's node index, for each of the last T_o steps. The
`GraphEncoder` runs masked self-attention along graph edges, then lets the robot's node
attend to every valid node, giving one vector z per observation.

Action: T_p lattice steps (dx, dy), each axis a one-hot over `step_values` mapped to
[-1, 1], so the diffusion model denoises a (T_p, 2 * len(step_values)) array (Chi et al.,
"Diffusion Policy", 2023, with the action space of DARE/GUIDE).

Denoiser: a Transformer rather than Diffusion Policy's 1-D temporal U-Net, because T_p = 8
is too short to survive a U-Net's downsamplings, and the conditioning (the diffusion step
and T_o observation vectors) is just a few tokens that cross-attention reads directly.
"""

from __future__ import annotations

import copy
import math
import warnings
from dataclasses import replace
from pathlib import Path
from typing import Any, Mapping

import numpy as np
import torch
import torch.nn as nn
import torch.nn.functional as F

from pipeline.models.configuration_diffusion import DiffusionPolicyConfig
from pipeline.models.ddpm_update import DDPMUpdate
from pipeline.models.exports import export_kind, read_weights_file, write_weights_file
from pipeline.prediction.graph_observation import GraphObservation

OBS_KEYS = ("features", "node_mask", "neighbors", "robot")


# ----------------------------------------------------------------------------- actions
def _step_table(config: DiffusionPolicyConfig, device: torch.device) -> torch.Tensor:
    return torch.tensor(config.step_values, dtype=torch.long, device=device)


def encode_actions(deltas: torch.Tensor, config: DiffusionPolicyConfig) -> torch.Tensor:
    """Lattice steps (..., T_p, 2) -> per-axis one-hot over `step_values`, in [-1, 1]: (..., T_p, action_dim)."""
    if deltas.shape[-1:] != (2,):
        raise ValueError(f"deltas must end in an axis of 2 (dx, dy), got shape {tuple(deltas.shape)}")
    table = _step_table(config, deltas.device)
    onehot = deltas.long().unsqueeze(-1) == table  # (..., T_p, 2, S)
    bad = ~onehot.any(-1)
    if bad.any():
        values = sorted(set(deltas[bad].tolist()))
        raise ValueError(f"deltas {values} are not in step_values {list(config.step_values)}")
    return (onehot.float() * 2.0 - 1.0).flatten(-2)


def decode_actions(x: torch.Tensor, config: DiffusionPolicyConfig) -> tuple[torch.Tensor, torch.Tensor]:
    """Encoded actions (..., T_p, action_dim) -> (argmax steps (..., T_p, 2) long, expected steps (..., T_p, 2)).

    `expected` weighs each bin's value by clamp((x + 1) / 2, 0), normalised per axis: a soft
    direction the planner can match against feasible neighbours when the argmax step is blocked.
    """
    if x.shape[-1] != config.action_dim:
        raise ValueError(f"last axis must be action_dim={config.action_dim}, got shape {tuple(x.shape)}")
    bins = x.unflatten(-1, (2, len(config.step_values)))  # (..., T_p, 2, S)
    table = _step_table(config, x.device)
    deltas = table[bins.argmax(-1)]
    weights = ((bins + 1.0) / 2.0).clamp(min=0.0)
    expected = (weights * table.to(x.dtype)).sum(-1) / weights.sum(-1).clamp(min=1e-8)
    return deltas, expected


# ----------------------------------------------------------------------------- graph encoder
def build_attention_mask(neighbors: torch.Tensor, node_mask: torch.Tensor) -> torch.Tensor:
    """(B, N, N) bool, True where node i may attend node j: j is i's neighbour or i itself, both valid.

    Rows of invalid (padded) nodes allow only the diagonal, so no softmax row is all-masked;
    no valid node ever attends an invalid one, so padded features cannot leak in.
    """
    batch, nodes, _ = neighbors.shape
    node_mask = node_mask.bool()
    # Scatter neighbour lists into an adjacency with one spare column that swallows the -1 padding.
    index = torch.where((neighbors >= 0) & (neighbors < nodes), neighbors, torch.full_like(neighbors, nodes))
    adjacency = torch.zeros(batch, nodes, nodes + 1, dtype=torch.bool, device=neighbors.device)
    adjacency.scatter_(2, index.long(), True)
    eye = torch.eye(nodes, dtype=torch.bool, device=neighbors.device).expand(batch, nodes, nodes)
    valid_pair = node_mask.unsqueeze(2) & node_mask.unsqueeze(1)
    return ((adjacency[..., :nodes] | eye) & valid_pair) | (eye & ~node_mask.unsqueeze(2))


class MaskedSelfAttentionLayer(nn.Module):
    """Pre-norm Transformer layer whose self-attention follows a per-graph boolean mask.

    Own layer instead of nn.TransformerEncoderLayer: scaled_dot_product_attention takes the
    (B, 1, N, N) "allowed" mask and broadcasts it over heads, with no per-head copy and no
    inversion of nn.MultiheadAttention's True-means-blocked convention.
    """

    def __init__(self, d_model: int, heads: int, dropout: float) -> None:
        super().__init__()
        self.heads = heads
        self.dropout = dropout
        self.norm1 = nn.LayerNorm(d_model)
        self.qkv = nn.Linear(d_model, 3 * d_model)
        self.out = nn.Linear(d_model, d_model)
        self.norm2 = nn.LayerNorm(d_model)
        self.ff = nn.Sequential(
            nn.Linear(d_model, 4 * d_model), nn.GELU(), nn.Dropout(dropout), nn.Linear(4 * d_model, d_model)
        )
        self.drop = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor, allowed: torch.Tensor) -> torch.Tensor:
        batch, nodes, width = x.shape
        q, k, v = self.qkv(self.norm1(x)).view(batch, nodes, 3, self.heads, width // self.heads).permute(2, 0, 3, 1, 4)
        attended = F.scaled_dot_product_attention(
            q, k, v, attn_mask=allowed.unsqueeze(1), dropout_p=self.dropout if self.training else 0.0
        )
        x = x + self.drop(self.out(attended.transpose(1, 2).reshape(batch, nodes, width)))
        return x + self.drop(self.ff(self.norm2(x)))


class GraphEncoder(nn.Module):
    """Node features -> edge-masked self-attention -> z (B, d_model) from three views of the robot's graph.

    z = project([robot node, robot's attention over all valid nodes, the window slots]). The
    window slots are the encoded nodes at each of the 5 x 5 lattice offsets around the robot
    (a learned "absent" vector where no neighbour sits), laid out in the same order as the
    action steps. Without them, the attention context of a freshly initialised encoder is
    close to an average over all nodes, nearly the same for every observation, and the
    denoiser learns only the actions' prior.
    """

    def __init__(self, config: DiffusionPolicyConfig) -> None:
        super().__init__()
        self.config = config
        d = config.d_model
        self.embed = nn.Linear(config.feature_dim, d)
        self.layers = nn.ModuleList(
            MaskedSelfAttentionLayer(d, config.heads, config.dropout) for _ in range(config.encoder_layers)
        )
        self.norm = nn.LayerNorm(d)
        self.robot_attention = nn.MultiheadAttention(d, config.heads, dropout=config.dropout, batch_first=True)
        self.radius = max(abs(v) for v in config.step_values)
        self.slots = (2 * self.radius + 1) ** 2
        self.slot_proj = nn.Linear(d, config.slot_width)
        self.absent = nn.Parameter(torch.zeros(self.slots, config.slot_width))
        self.project = nn.Linear(2 * d + self.slots * config.slot_width, d)  # [robot, context, slots] -> z

    def window_slots(
        self,
        h: torch.Tensor,
        features: torch.Tensor,
        node_mask: torch.Tensor,
        neighbors: torch.Tensor,
        robot: torch.Tensor,
    ) -> torch.Tensor:
        """(B, slots * slot_width): the robot's neighbours' encodings placed at their lattice offsets."""
        batch = h.shape[0]
        rows = torch.arange(batch, device=h.device)
        listed = neighbors[rows, robot.long()].long()  # (B, M)
        present = (listed >= 0) & node_mask.gather(1, listed.clamp(min=0))
        index = listed.clamp(min=0)
        offsets = torch.round(
            features[rows[:, None], index, 0:2].float() * self.config.window_scale
        ).long()  # (B, M, 2)
        inside = present & (offsets.abs() <= self.radius).all(-1)
        width = 2 * self.radius + 1
        slot = (offsets[..., 1] + self.radius) * width + (offsets[..., 0] + self.radius)
        slot = torch.where(inside, slot, torch.full_like(slot, self.slots))  # a spare slot swallows the rest
        values = self.slot_proj(h[rows[:, None], index])  # (B, M, slot_width)
        filled = torch.zeros(batch, self.slots + 1, values.shape[-1], device=h.device, dtype=values.dtype)
        filled = filled.scatter(1, slot.unsqueeze(-1).expand_as(values), values)
        seen = torch.zeros(batch, self.slots + 1, dtype=torch.bool, device=h.device).scatter(1, slot, inside)
        centre = self.slot_proj(h[rows, robot.long()])  # the robot's own node sits at the centre slot
        filled[:, self.slots // 2] = centre
        seen[:, self.slots // 2] = True
        slots = torch.where(seen[:, : self.slots, None], filled[:, : self.slots], self.absent.expand(batch, -1, -1))
        return slots.flatten(1)

    def forward(
        self, features: torch.Tensor, node_mask: torch.Tensor, neighbors: torch.Tensor, robot: torch.Tensor
    ) -> torch.Tensor:
        """features (B, N, F), node_mask (B, N), neighbors (B, N, M) with -1 padding, robot (B,) -> (B, d_model)."""
        if features.shape[-1] != self.config.feature_dim:
            raise ValueError(
                f"features must have {self.config.feature_dim} channels, got shape {tuple(features.shape)}"
            )
        node_mask = node_mask.bool()
        allowed = build_attention_mask(neighbors, node_mask)
        h = self.embed(features.float())
        for layer in self.layers:
            h = layer(h, allowed)
        h = self.norm(h)
        robot_h = h[torch.arange(h.shape[0], device=h.device), robot.long()]  # (B, d)
        context, _ = self.robot_attention(
            robot_h.unsqueeze(1), h, h, key_padding_mask=~node_mask, need_weights=False
        )  # key_padding_mask: True = ignore
        slots = self.window_slots(h, features, node_mask, neighbors, robot)
        return self.project(torch.cat([robot_h, context.squeeze(1), slots], dim=-1))


# ----------------------------------------------------------------------------- denoiser
def sinusoidal_embedding(timesteps: torch.Tensor, dim: int, max_period: float = 10000.0) -> torch.Tensor:
    """Transformer sinusoidal embedding of diffusion steps (B,) -> (B, dim) ([sin, cos] halves)."""
    half = dim // 2
    frequencies = torch.exp(
        -math.log(max_period) * torch.arange(half, device=timesteps.device, dtype=torch.float32) / half
    )
    angles = timesteps.float().unsqueeze(-1) * frequencies
    return torch.cat([angles.sin(), angles.cos()], dim=-1)


class DenoiserLayer(nn.Module):
    """Pre-norm Transformer decoder layer: self-attention over action tokens (no causal mask),
    cross-attention to the conditioning tokens, GELU feed-forward.

    The maths of nn.TransformerDecoderLayer(norm_first=True, activation="gelu"), written on
    scaled_dot_product_attention: with 8 tokens the per-call checks of nn.MultiheadAttention
    cost more than the arithmetic, and this layer is run K * denoiser_layers times per plan.
    """

    def __init__(self, d_model: int, heads: int, dropout: float) -> None:
        super().__init__()
        self.heads = heads
        self.dropout = dropout
        self.norm1 = nn.LayerNorm(d_model)
        self.qkv = nn.Linear(d_model, 3 * d_model)
        self.self_out = nn.Linear(d_model, d_model)
        self.norm2 = nn.LayerNorm(d_model)
        self.query = nn.Linear(d_model, d_model)
        self.key_value = nn.Linear(d_model, 2 * d_model)
        self.cross_out = nn.Linear(d_model, d_model)
        self.norm3 = nn.LayerNorm(d_model)
        self.ff = nn.Sequential(
            nn.Linear(d_model, 4 * d_model), nn.GELU(), nn.Dropout(dropout), nn.Linear(4 * d_model, d_model)
        )
        self.drop = nn.Dropout(dropout)

    def forward(self, x: torch.Tensor, memory: torch.Tensor) -> torch.Tensor:
        batch, tokens, width = x.shape
        head_dim = width // self.heads
        dropout_p = self.dropout if self.training else 0.0
        q, k, v = self.qkv(self.norm1(x)).view(batch, tokens, 3, self.heads, head_dim).permute(2, 0, 3, 1, 4)
        attended = F.scaled_dot_product_attention(q, k, v, dropout_p=dropout_p)
        x = x + self.drop(self.self_out(attended.transpose(1, 2).reshape(batch, tokens, width)))
        q = self.query(self.norm2(x)).view(batch, tokens, self.heads, head_dim).transpose(1, 2)
        k, v = self.key_value(memory).view(batch, memory.shape[1], 2, self.heads, head_dim).permute(2, 0, 3, 1, 4)
        attended = F.scaled_dot_product_attention(q, k, v, dropout_p=dropout_p)
        x = x + self.drop(self.cross_out(attended.transpose(1, 2).reshape(batch, tokens, width)))
        return x + self.drop(self.ff(self.norm3(x)))


class NoisePredictionNet(nn.Module):
    """Transformer decoder over T_p action tokens, cross-attending [step token, T_o observation tokens]."""

    def __init__(self, config: DiffusionPolicyConfig) -> None:
        super().__init__()
        self.config = config
        d = config.d_model
        self.action_in = nn.Linear(config.action_dim, d)
        self.action_pos = nn.Parameter(torch.zeros(1, config.horizon, d))
        self.step_mlp = nn.Sequential(nn.Linear(d, 4 * d), nn.Mish(), nn.Linear(4 * d, d))
        self.obs_pos = nn.Parameter(torch.zeros(1, config.obs_steps, d))
        self.memory_norm = nn.LayerNorm(d)
        # Every action token also receives the whole conditioning additively (as FiLM does in
        # Diffusion Policy's U-Net): with cross-attention alone the net learned the actions'
        # prior and ignored the observation (shuffling z barely moved its output).
        self.condition_in = nn.Linear((1 + config.obs_steps) * d, d)
        self.layers = nn.ModuleList(
            DenoiserLayer(d, config.heads, config.dropout) for _ in range(config.denoiser_layers)
        )
        self.norm = nn.LayerNorm(d)
        self.action_out = nn.Linear(d, config.action_dim)
        nn.init.normal_(self.action_pos, std=0.02)
        nn.init.normal_(self.obs_pos, std=0.02)

    def condition(self, timesteps: torch.Tensor, obs_z: torch.Tensor) -> torch.Tensor:
        """Memory tokens [step token, T_o observation tokens]: timesteps (B,), obs_z (B, T_o, d) -> (B, 1 + T_o, d)."""
        if obs_z.shape[1] != self.config.obs_steps:
            raise ValueError(f"expected T_o={self.config.obs_steps} observations, got {obs_z.shape[1]}")
        step_token = self.step_mlp(sinusoidal_embedding(timesteps, self.config.d_model)).unsqueeze(1)
        # One LayerNorm puts the step MLP's output and the encoder's z on a common scale before
        # every layer's cross-attention reads them (they do not change across layers).
        return self.memory_norm(torch.cat([step_token, obs_z + self.obs_pos], dim=1))

    def denoise(self, noisy_actions: torch.Tensor, memory: torch.Tensor) -> torch.Tensor:
        """noisy_actions (B, T_p, A) and memory from `condition` -> predicted noise (B, T_p, A)."""
        if noisy_actions.shape[1] != self.config.horizon:
            raise ValueError(f"expected T_p={self.config.horizon} actions, got {noisy_actions.shape[1]}")
        x = self.action_in(noisy_actions) + self.action_pos + self.condition_in(memory.flatten(1)).unsqueeze(1)
        for layer in self.layers:
            x = layer(x, memory)
        return self.action_out(self.norm(x))

    def forward(self, noisy_actions: torch.Tensor, timesteps: torch.Tensor, obs_z: torch.Tensor) -> torch.Tensor:
        """noisy_actions (B, T_p, A), timesteps (B,) long, obs_z (B, T_o, d_model) -> predicted noise (B, T_p, A)."""
        timesteps = timesteps.reshape(-1).expand(noisy_actions.shape[0]) if timesteps.numel() == 1 else timesteps
        return self.denoise(noisy_actions, self.condition(timesteps, obs_z))


class TracedDenoiser:
    """Frozen TorchScript traces of `NoisePredictionNet.denoise`, one per input shape, for sampling.

    The denoiser runs K times per decision on a handful of tokens, so Python dispatch, not
    arithmetic, is most of its cost, and the trace removes most of the Python. The weights are frozen into the trace, so it is
    for an eval-mode model whose weights no longer change (`DiffusionPolicy.trace_denoiser`).
    """

    def __init__(self, net: NoisePredictionNet) -> None:
        self.net = net
        self._traces: dict[tuple, torch.jit.ScriptModule] = {}

    def __call__(self, noisy_actions: torch.Tensor, memory: torch.Tensor) -> torch.Tensor:
        key = (tuple(noisy_actions.shape), tuple(memory.shape), noisy_actions.dtype, noisy_actions.device)
        if key not in self._traces:
            self.net.denoise(noisy_actions, memory)  # the shape checks, eagerly, before they become constants
            with warnings.catch_warnings(), torch.no_grad():
                warnings.simplefilter("ignore")  # traced shapes are constants for this key: intended
                module = torch.jit.trace_module(self.net, {"denoise": (noisy_actions, memory)}, check_trace=False)
                self._traces[key] = torch.jit.freeze(module.eval(), preserved_attrs=["denoise"])
        return self._traces[key].denoise(noisy_actions, memory)


# ----------------------------------------------------------------------------- policy
class DiffusionPolicy(nn.Module):
    """Graph encoder + noise-prediction net + diffusers schedulers (DDPM for training, DDPM/DDIM to sample)."""

    def __init__(self, config: DiffusionPolicyConfig) -> None:
        # Imported here: diffusers takes about 2 s to import, which every user of
        # pipeline.models (the inpainter stages too) would otherwise pay.
        from diffusers import DDIMScheduler, DDPMScheduler

        super().__init__()
        self.config = config
        self.encoder = GraphEncoder(config)
        self.noise_net = NoisePredictionNet(config)
        # Any: the DDPMScheduler that diffusers' lazy imports show a type checker has no methods
        self.noise_scheduler: Any = DDPMScheduler(
            num_train_timesteps=config.num_train_timesteps,
            beta_schedule=config.beta_schedule,
            clip_sample=config.clip_sample,
            prediction_type=config.prediction_type,
        )
        sampler_class = DDIMScheduler if config.sampler == "ddim" else DDPMScheduler
        # Same betas and prediction type as training; only the update rule differs.
        self.inference_scheduler = sampler_class.from_config(self.noise_scheduler.config)
        self.traced_denoiser: TracedDenoiser | None = None
        self.ddpm_updates: dict[tuple, DDPMUpdate] = {}  # per (K, device): the DDPM step's coefficients

    def trace_denoiser(self) -> "DiffusionPolicy":
        """Sample with frozen TorchScript traces of the denoiser (the same outputs, faster per step).

        For a trained policy in eval mode (the planners call it once per loaded checkpoint);
        `train()` drops the traces, since they hold a copy of the weights.
        """
        self.eval()
        self.traced_denoiser = TracedDenoiser(self.noise_net)
        return self

    def train(self, mode: bool = True) -> "DiffusionPolicy":
        if mode:
            self.traced_denoiser = None
        return super().train(mode)

    def num_parameters(self) -> int:
        return sum(p.numel() for p in self.parameters())

    def _device(self) -> torch.device:
        return next(self.parameters()).device

    def encode_observations(
        self, features: torch.Tensor, node_mask: torch.Tensor, neighbors: torch.Tensor, robot: torch.Tensor
    ) -> torch.Tensor:
        """features (B, T_o, N, F), node_mask (B, T_o, N), neighbors (B, T_o, N, M), robot (B, T_o) -> (B, T_o, d_model)."""
        batch, steps = features.shape[:2]
        if steps != self.config.obs_steps:
            raise ValueError(f"expected T_o={self.config.obs_steps} observations, got {steps}")
        z = self.encoder(features.flatten(0, 1), node_mask.flatten(0, 1), neighbors.flatten(0, 1), robot.flatten(0, 1))
        return z.view(batch, steps, -1)

    @torch.inference_mode()
    def encode(self, observation: GraphObservation) -> torch.Tensor:
        """(1, d_model): one global graph as the policy sees it, encoded. A receding-horizon
        planner keeps each graph's encoding for the T_o decisions that condition on it."""
        return self.encoder(
            torch.from_numpy(observation.features)[None],
            torch.from_numpy(observation.node_mask)[None],
            torch.from_numpy(observation.neighbors.astype(np.int64))[None],
            torch.tensor([observation.robot]),
        )

    def _encode_obs_dict(self, obs: Mapping[str, torch.Tensor]) -> torch.Tensor:
        missing = [key for key in OBS_KEYS if key not in obs]
        if missing:
            raise ValueError(f"observation is missing keys {missing}; needs {list(OBS_KEYS)}")
        device = self._device()
        return self.encode_observations(*(obs[key].to(device) for key in OBS_KEYS))

    def compute_loss(self, batch: Mapping[str, Any]) -> torch.Tensor:
        """Denoising loss on a batch: MSE between the net's output and the scheduler's target (noise for epsilon)."""
        obs_z = self._encode_obs_dict(batch)
        clean = encode_actions(batch["actions"].to(obs_z.device), self.config)
        if clean.shape[1] != self.config.horizon:
            raise ValueError(f"expected T_p={self.config.horizon} actions, got {clean.shape[1]}")
        noise = torch.randn_like(clean)
        timesteps = torch.randint(0, self.config.num_train_timesteps, (clean.shape[0],), device=clean.device)
        noisy = self.noise_scheduler.add_noise(clean, noise, timesteps)
        predicted = self.noise_net(noisy, timesteps, obs_z)
        if self.config.prediction_type == "epsilon":
            target = noise
        elif self.config.prediction_type == "sample":
            target = clean
        else:  # v_prediction
            target = self.noise_scheduler.get_velocity(clean, noise, timesteps)
        return F.mse_loss(predicted, target)

    def with_sampler(self, sampler: str) -> "DiffusionPolicy":
        """A shallow copy (weights shared) that samples with another update rule: ddpm or ddim."""
        from diffusers import DDIMScheduler, DDPMScheduler

        variant = copy.copy(self)
        variant.config = replace(self.config, sampler=sampler)
        scheduler_class = DDIMScheduler if sampler == "ddim" else DDPMScheduler
        variant.inference_scheduler = scheduler_class.from_config(self.noise_scheduler.config)
        variant.ddpm_updates = {}
        return variant

    def _conditioning(self, obs: Mapping[str, torch.Tensor] | torch.Tensor) -> torch.Tensor:
        """(B, T_o, d): `obs` encoded, or `obs` itself when it is already an encoding."""
        return obs if isinstance(obs, torch.Tensor) else self._encode_obs_dict(obs)

    @torch.no_grad()
    def sample(
        self,
        obs: Mapping[str, torch.Tensor] | torch.Tensor,
        num_inference_steps: int | None = None,
        generator: torch.Generator | None = None,
    ) -> torch.Tensor:
        """Denoise Gaussian noise into encoded actions (B, T_p, action_dim) in [-1, 1].

        `obs` is the last T_o observations (a mapping of OBS_KEYS tensors) or their encoding
        (B, T_o, d), which a receding-horizon planner keeps so that each graph is encoded once.
        The memory tokens of all K steps are built in one batched call before the loop, which
        then runs only the decoder layers and the scheduler.
        """
        obs_z = self._conditioning(obs)
        batch = obs_z.shape[0]
        shape = (batch, self.config.horizon, self.config.action_dim)
        x = torch.randn(shape, generator=generator, device=obs_z.device, dtype=obs_z.dtype)
        scheduler = self.inference_scheduler
        steps = self.config.num_inference_steps if num_inference_steps is None else num_inference_steps
        scheduler.set_timesteps(steps, device=obs_z.device)
        timesteps = scheduler.timesteps
        memories = self.noise_net.condition(
            timesteps.repeat_interleave(batch), obs_z.repeat(len(timesteps), 1, 1)
        ).unflatten(0, (len(timesteps), batch))  # (K, B, 1 + T_o, d)
        denoise = self.traced_denoiser or self.noise_net.denoise
        update = self._ddpm_update(scheduler, steps, obs_z.device)
        for k, (t, memory) in enumerate(zip(timesteps, memories)):
            predicted = denoise(x, memory)
            if update is None:
                x = scheduler.step(predicted, t, x, generator=generator).prev_sample
            else:
                x = update(k, predicted, x, generator)
        return x.clamp(-1.0, 1.0)

    def _ddpm_update(self, scheduler, steps: int, device: torch.device) -> DDPMUpdate | None:
        """The DDPM step with its coefficients made once for these K steps (bit for bit diffusers'
        `step`), or None for a scheduler it does not cover (DDIM, other variances)."""
        if not DDPMUpdate.supports(scheduler):
            return None
        key = (int(steps), str(device))
        if key not in self.ddpm_updates:
            self.ddpm_updates[key] = DDPMUpdate(scheduler)
        return self.ddpm_updates[key]

    @torch.no_grad()
    def predict_action(
        self,
        obs: Mapping[str, torch.Tensor] | torch.Tensor,
        num_inference_steps: int | None = None,
        generator: torch.Generator | None = None,
    ) -> dict[str, torch.Tensor]:
        """T_p actions for the last T_o observations (or their encoding), K denoising steps:
        {"deltas": (B, T_p, 2) long, "expected": (B, T_p, 2), "raw": (B, T_p, action_dim)}."""
        raw = self.sample(obs, num_inference_steps=num_inference_steps, generator=generator)
        deltas, expected = decode_actions(raw, self.config)
        return {"deltas": deltas, "expected": expected, "raw": raw}


# ----------------------------------------------------------------------------- export / load
def export_policy(policy: DiffusionPolicy, path: str | Path, **extra: Any) -> Path:
    return write_weights_file({"config": policy.config.to_dict(), "state_dict": policy.state_dict(), **extra}, path)


def read_policy_export(path: str | Path) -> dict[str, Any]:
    """The export's dict (config, EMA state_dict, metadata); loads tensors only, never pickled code."""
    data = read_weights_file(path, "a planner checkpoint")
    if export_kind(data) == "inpainter":
        raise ValueError(
            f"{path}: an inpainter export, not a planner policy (pass it as the inpainter: inpainter=PATH)"
        )
    if "config" not in data or "state_dict" not in data:
        raise ValueError(f"{path}: not a planner export (expected keys config and state_dict)")
    return data


def load_policy(path: str | Path) -> tuple[DiffusionPolicy, dict[str, Any]]:
    """(the exported EMA policy in eval mode, the export's metadata)."""
    data = read_policy_export(path)
    policy = DiffusionPolicy(DiffusionPolicyConfig.from_dict(data["config"]))
    policy.load_state_dict(data["state_dict"])
    meta = {k: v for k, v in data.items() if k not in ("state_dict",)}
    return policy.eval(), meta
