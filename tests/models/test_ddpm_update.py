"""The DDPM step with its coefficients made once: bit for bit diffusers' `DDPMScheduler.step`."""

from __future__ import annotations

import dataclasses

import pytest
import torch
from test_modeling_diffusion import TINY, observation

from pipeline.models import DiffusionPolicy
from pipeline.models.ddpm_update import DDPMUpdate

pytestmark = pytest.mark.usefixtures("one_torch_thread")


@pytest.mark.parametrize("prediction_type", ["sample", "epsilon"])
@pytest.mark.parametrize("steps", [1, 7, 30])
def test_a_sample_is_the_schedulers_bit_for_bit(prediction_type, steps, monkeypatch):
    torch.manual_seed(0)
    policy = DiffusionPolicy(dataclasses.replace(TINY, prediction_type=prediction_type)).eval()
    obs = observation(TINY, batch=3, seed=4)
    fast = policy.sample(obs, num_inference_steps=steps, generator=torch.Generator().manual_seed(11))
    assert (steps, "cpu") in policy.ddpm_updates  # the sample went through DDPMUpdate
    monkeypatch.setattr(DDPMUpdate, "supports", staticmethod(lambda scheduler: False))
    slow = policy.sample(obs, num_inference_steps=steps, generator=torch.Generator().manual_seed(11))
    assert torch.equal(fast, slow)


def test_one_step_is_the_schedulers_step_with_its_noise():
    policy = DiffusionPolicy(TINY)
    scheduler = policy.inference_scheduler
    scheduler.set_timesteps(10)
    update = DDPMUpdate(scheduler)
    x = torch.randn(2, TINY.horizon, TINY.action_dim, generator=torch.Generator().manual_seed(1))
    out = torch.randn(2, TINY.horizon, TINY.action_dim, generator=torch.Generator().manual_seed(2)) * 2
    for k, t in enumerate(scheduler.timesteps):
        ours = update(k, out, x, torch.Generator().manual_seed(k))
        theirs = scheduler.step(out, t, x, generator=torch.Generator().manual_seed(k)).prev_sample
        assert torch.equal(ours, theirs), (k, int(t))


def test_ddim_keeps_diffusers_step():
    ddim = DiffusionPolicy(TINY).with_sampler("ddim")
    assert not DDPMUpdate.supports(ddim.inference_scheduler)
    with pytest.raises(ValueError, match="DDPMUpdate covers DDPMScheduler"):
        DDPMUpdate(ddim.inference_scheduler)
    ddim.eval().sample(observation(TINY), num_inference_steps=5, generator=torch.Generator().manual_seed(0))
    assert ddim.ddpm_updates == {}
