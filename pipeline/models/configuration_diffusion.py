"""Configuration of the GUIDE/DARE diffusion policy (graph encoder + noise-prediction network).

The defaults are a small CPU profile (about 0.4 M parameters) that trains on a laptop and
samples an action sequence in milliseconds; `DiffusionPolicyConfig.paper()` gives the
paper-scale widths and depths. Actions are lattice steps per axis, in node units: the
paper's {-8, -4, 0, 4, 8} m at a node spacing d_n = 4 m is `step_values=(-2, -1, 0, 1, 2)`.
"""

from __future__ import annotations

from dataclasses import asdict
from typing import Annotated, Any

from pipeline.common.config import config_dataclass, flag, list_of, positive, real, text, validate, whole

SAMPLERS = ("ddpm", "ddim")
BETA_SCHEDULES = ("linear", "scaled_linear", "squaredcos_cap_v2")
PREDICTION_TYPES = ("epsilon", "sample", "v_prediction")


@config_dataclass
class DiffusionPolicyConfig:
    """Sizes of the graph encoder and the denoiser, the action horizon and the noise schedule.

    Frozen: a model is built from one config and the config is saved next to its weights, so
    it must not change under the model. Use `dataclasses.replace` to derive a variant.
    """

    # Observation graph
    feature_dim: Annotated[int, whole(1, note="features per node")] = 7  # F
    max_nodes: Annotated[int, whole(1, note="nodes per padded graph")] = 320  # N
    max_neighbors: Annotated[int, whole(1, note="neighbour slots per node")] = 25  # M (-1 padded)
    # Network widths and depths
    d_model: Annotated[int, whole(1)] = 64
    heads: Annotated[int, whole(1)] = 4
    encoder_layers: Annotated[int, whole(1)] = 3
    denoiser_layers: Annotated[int, whole(1)] = 4
    dropout: Annotated[float, real(0.0, 1.0, high_open=True)] = 0.0
    # Horizons (Diffusion Policy's T_p, T_o, T_a)
    horizon: Annotated[int, whole(1, note="predicted action steps")] = 8  # T_p
    obs_steps: Annotated[int, whole(1, note="conditioning observations")] = 2  # T_o
    action_steps: Annotated[int, whole(1, note="executed action steps before replanning")] = 2  # T_a
    # Action lattice: the step per axis, in node units (a tuple once made: YAML and JSON give lists)
    step_values: Annotated[list[int], list_of(whole(None, note="lattice steps"), min_length=2)] = (-2, -1, 0, 1, 2)  # type: ignore[assignment]  # a tuple default, as the field is once made
    # The robot's 5 x 5 lattice window as slots of z (see GraphEncoder): feature units (dx, dy)
    # per lattice step: GlobalGraphConfig.position_scale_nodes (dx, dy are in units of 10 node spacings).
    window_scale: Annotated[float, positive()] = 10.0
    slot_width: Annotated[int, whole(1)] = 8  # width of each window slot in z
    # Noise schedule (diffusers scheduler arguments)
    num_train_timesteps: Annotated[int, whole(1)] = 100
    beta_schedule: Annotated[str, text(BETA_SCHEDULES)] = "squaredcos_cap_v2"
    # x0: makes the net use the observation
    prediction_type: Annotated[str, text(PREDICTION_TYPES)] = "sample"
    clip_sample: Annotated[bool, flag()] = True
    # Sampling
    num_inference_steps: Annotated[int, whole(1)] = 30  # K
    sampler: Annotated[str, text(SAMPLERS)] = "ddpm"

    def __post_init__(self) -> None:
        # A tuple, so that the config stays hashable and comparable.
        object.__setattr__(self, "step_values", tuple(self.step_values))
        if self.d_model % self.heads != 0:
            raise ValueError(f"d_model ({self.d_model}) must be divisible by heads ({self.heads})")
        if self.d_model % 2 != 0:
            raise ValueError(f"d_model ({self.d_model}) must be even (sinusoidal step embedding)")
        if self.horizon < self.action_steps:
            raise ValueError(
                f"need horizon >= action_steps, got horizon={self.horizon}, action_steps={self.action_steps}"
            )
        if len(set(self.step_values)) != len(self.step_values):
            raise ValueError(f"step_values must be distinct, got {list(self.step_values)!r}")
        if self.num_inference_steps > self.num_train_timesteps:
            raise ValueError(
                f"num_inference_steps ({self.num_inference_steps}) must not exceed "
                f"num_train_timesteps ({self.num_train_timesteps})"
            )

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
    def from_dict(cls, values: dict[str, Any] | None, root: str = "model") -> "DiffusionPolicyConfig":
        """Build from a dict (params.yaml, a saved model); a refused value or an unknown key is a
        one-line ValueError naming it as `root.key`."""
        return validate(cls, values, root)

    @classmethod
    def paper(cls, **overrides: Any) -> "DiffusionPolicyConfig":
        """Paper-scale widths and depths (d_model 256, 8 heads, 6 encoder and 8 denoiser layers)."""
        values: dict[str, Any] = dict(d_model=256, heads=8, encoder_layers=6, denoiser_layers=8)
        values.update(overrides)
        return cls(**values)
