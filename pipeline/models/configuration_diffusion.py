"""Configuration of the GUIDE/DARE diffusion policy (graph encoder + noise-prediction network).

The defaults are a small CPU profile (about 0.4 M parameters) that trains on a laptop and
samples an action sequence in milliseconds; `DiffusionPolicyConfig.paper()` gives the
paper-scale widths and depths. Actions are lattice steps per axis, in node units: the
paper's {-8, -4, 0, 4, 8} m at a node spacing d_n = 4 m is `step_values=(-2, -1, 0, 1, 2)`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from typing import Any

from pipeline.common.params import dataclass_from_dict

SAMPLERS = ("ddpm", "ddim")
BETA_SCHEDULES = ("linear", "scaled_linear", "squaredcos_cap_v2")
PREDICTION_TYPES = ("epsilon", "sample", "v_prediction")


@dataclass(frozen=True)
class DiffusionPolicyConfig:
    """Sizes of the graph encoder and the denoiser, the action horizon and the noise schedule.

    Frozen: a model is built from one config and the config is saved next to its weights, so
    it must not change under the model. Use `dataclasses.replace` to derive a variant.
    """

    # Observation graph
    feature_dim: int = 7  # F: features per node
    max_nodes: int = 320  # N: nodes per padded graph
    max_neighbors: int = 25  # M: neighbour slots per node (-1 padded)
    # Network widths and depths
    d_model: int = 64
    heads: int = 4
    encoder_layers: int = 3
    denoiser_layers: int = 4
    dropout: float = 0.0
    # Horizons (Diffusion Policy's T_p, T_o, T_a)
    horizon: int = 8  # T_p: predicted action steps
    obs_steps: int = 2  # T_o: conditioning observations
    action_steps: int = 2  # T_a: executed action steps before replanning
    # Action lattice: the step per axis, in node units
    step_values: tuple[int, ...] = (-2, -1, 0, 1, 2)
    # The robot's 5 x 5 lattice window as slots of z (see GraphEncoder): feature units (dx, dy)
    # per lattice step: GlobalGraphConfig.position_scale_nodes (dx, dy are in units of 10 node spacings).
    window_scale: float = 10.0
    slot_width: int = 8  # width of each window slot in z
    # Noise schedule (diffusers scheduler arguments)
    num_train_timesteps: int = 100
    beta_schedule: str = "squaredcos_cap_v2"
    prediction_type: str = "sample"  # x0: makes the net use the observation (docs/findings.md, "The learned policy")
    clip_sample: bool = True
    # Sampling
    num_inference_steps: int = 30  # K
    sampler: str = "ddpm"

    def __post_init__(self) -> None:
        # YAML and JSON give lists; keep the tuple so the config stays hashable and comparable.
        object.__setattr__(self, "step_values", tuple(self.step_values))
        for name in ("feature_dim", "max_nodes", "max_neighbors", "d_model", "heads", "encoder_layers",
                     "denoiser_layers", "horizon", "obs_steps", "action_steps", "num_train_timesteps",
                     "num_inference_steps", "slot_width"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        if self.d_model % self.heads != 0:
            raise ValueError(f"d_model ({self.d_model}) must be divisible by heads ({self.heads})")
        if self.d_model % 2 != 0:
            raise ValueError(f"d_model ({self.d_model}) must be even (sinusoidal step embedding)")
        if not 0.0 <= self.dropout < 1.0:
            raise ValueError(f"dropout must lie in [0, 1), got {self.dropout!r}")
        if not self.horizon >= self.action_steps >= 1:
            raise ValueError(f"need horizon >= action_steps >= 1, got horizon={self.horizon}, action_steps={self.action_steps}")
        if len(self.step_values) < 2:
            raise ValueError(f"step_values needs at least 2 values, got {self.step_values!r}")
        if any(isinstance(v, bool) or not isinstance(v, int) for v in self.step_values):
            raise ValueError(f"step_values must be integers, got {self.step_values!r}")
        if len(set(self.step_values)) != len(self.step_values):
            raise ValueError(f"step_values must be distinct, got {self.step_values!r}")
        if self.beta_schedule not in BETA_SCHEDULES:
            raise ValueError(f"beta_schedule {self.beta_schedule!r}: use one of {list(BETA_SCHEDULES)}")
        if self.prediction_type not in PREDICTION_TYPES:
            raise ValueError(f"prediction_type {self.prediction_type!r}: use one of {list(PREDICTION_TYPES)}")
        if not isinstance(self.clip_sample, bool):
            raise ValueError(f"clip_sample must be a bool, got {self.clip_sample!r}")
        if self.num_inference_steps > self.num_train_timesteps:
            raise ValueError(
                f"num_inference_steps ({self.num_inference_steps}) must not exceed num_train_timesteps ({self.num_train_timesteps})"
            )
        if not self.window_scale > 0:
            raise ValueError(f"window_scale must be > 0, got {self.window_scale!r}")
        if self.sampler not in SAMPLERS:
            raise ValueError(f"sampler {self.sampler!r}: use one of {list(SAMPLERS)}")

    @property
    def action_dim(self) -> int:
        """Width of one encoded action: a one-hot over `step_values` for each of the 2 axes."""
        return 2 * len(self.step_values)

    def to_dict(self) -> dict[str, Any]:
        """Plain values (step_values as a list), ready for YAML or JSON."""
        values = asdict(self)
        values["step_values"] = list(self.step_values)
        return values

    @classmethod
    def from_dict(cls, values: dict[str, Any] | None) -> "DiffusionPolicyConfig":
        """Build from a dict (params.yaml, a saved model); unknown keys are an error, not ignored."""
        return dataclass_from_dict(cls, values, "diffusion policy config keys")

    @classmethod
    def paper(cls, **overrides: Any) -> "DiffusionPolicyConfig":
        """Paper-scale widths and depths (d_model 256, 8 heads, 6 encoder and 8 denoiser layers)."""
        values: dict[str, Any] = dict(d_model=256, heads=8, encoder_layers=6, denoiser_layers=8)
        values.update(overrides)
        return cls(**values)
