"""diffusers' DDPM update for one set of sampling timesteps, its coefficients computed once.

`DDPMScheduler.step` finds the previous timestep by searching its timestep list and recomputes
its coefficients from `alphas_cumprod` at every call. A planner samples K steps per decision on
a few tokens, so on a CPU that bookkeeping is a fifth of the denoising. `DDPMUpdate` does the
same arithmetic on the same 0-dim tensors as `step` (prediction of the sample or the noise,
clipping, the "fixed_small" variance, the noise drawn by diffusers' `randn_tensor` from the
same generator), so a sample is bit for bit the scheduler's. Other scheduler settings keep
diffusers' own step (`DDPMUpdate.supports`).
"""

from __future__ import annotations

import torch

SUPPORTED_PREDICTIONS = ("sample", "epsilon")


class DDPMUpdate:
    """x_t -> x_{t-1} for each timestep of `scheduler.timesteps` (after its `set_timesteps`)."""

    def __init__(self, scheduler) -> None:
        if not self.supports(scheduler):
            raise ValueError(
                "DDPMUpdate covers DDPMScheduler with variance_type fixed_small, no thresholding and "
                f"prediction_type in {SUPPORTED_PREDICTIONS}"
            )
        from diffusers.utils.torch_utils import randn_tensor  # diffusers' own noise draw: the same numbers

        config = scheduler.config
        self.randn = randn_tensor
        self.prediction_type = config.prediction_type
        self.clip = float(config.clip_sample_range) if config.clip_sample else None
        self.timesteps = [int(t) for t in scheduler.timesteps]
        self.coefficients = [self._coefficients(scheduler, k) for k in range(len(self.timesteps))]

    @staticmethod
    def supports(scheduler) -> bool:
        config = scheduler.config
        return (
            type(scheduler).__name__ == "DDPMScheduler"
            and config.variance_type == "fixed_small"
            and not config.thresholding
            and config.prediction_type in SUPPORTED_PREDICTIONS
        )

    def _coefficients(self, scheduler, k: int) -> dict:
        """The step's tensors, as `DDPMScheduler.step` and `_get_variance` compute them."""
        t = self.timesteps[k]
        prev_t = self.timesteps[k + 1] if k + 1 < len(self.timesteps) else -1
        alpha_prod_t = scheduler.alphas_cumprod[t]
        alpha_prod_t_prev = scheduler.alphas_cumprod[prev_t] if prev_t >= 0 else scheduler.one
        beta_prod_t = 1 - alpha_prod_t
        beta_prod_t_prev = 1 - alpha_prod_t_prev
        current_alpha_t = alpha_prod_t / alpha_prod_t_prev
        current_beta_t = 1 - current_alpha_t
        variance = torch.clamp((1 - alpha_prod_t_prev) / (1 - alpha_prod_t) * current_beta_t, min=1e-20)
        return {
            "t": t,
            "sqrt_alpha_prod_t": alpha_prod_t ** (0.5),
            "sqrt_beta_prod_t": beta_prod_t ** (0.5),
            "x0": (alpha_prod_t_prev ** (0.5) * current_beta_t) / beta_prod_t,
            "xt": current_alpha_t ** (0.5) * beta_prod_t_prev / beta_prod_t,
            "std": variance**0.5,
        }

    def __call__(
        self, k: int, model_output: torch.Tensor, sample: torch.Tensor, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """The sample before step `k` (an index into the timesteps) given the net's output at it."""
        c = self.coefficients[k]
        if self.prediction_type == "sample":
            original = model_output
        else:  # epsilon
            original = (sample - c["sqrt_beta_prod_t"] * model_output) / c["sqrt_alpha_prod_t"]
        if self.clip is not None:
            original = original.clamp(-self.clip, self.clip)
        previous = c["x0"] * original + c["xt"] * sample
        variance = 0
        if c["t"] > 0:
            noise = self.randn(
                model_output.shape, generator=generator, device=model_output.device, dtype=model_output.dtype
            )
            variance = c["std"] * noise
        return previous + variance
