"""Big LaMa's generator weights in our InpainterModel: the state dict read from the published
checkpoint, its first and last convolutions adapted to our channels.
"""

from __future__ import annotations

from typing import Mapping, Optional

import torch

from pipeline.models.modeling_inpainter import InpainterModel

FIRST_CONV = "model.1.ffc.convl2l.weight"


def last_conv_prefix(model: InpainterModel) -> str:
    return f"model.{len(model.model) - 2}"


def generator_state_dict(state_dict: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """The generator's tensors of a LaMa checkpoint: keys under `generator.` (prefix removed),
    or the dict itself when it holds bare generator keys (`model.*`)."""
    if "state_dict" in state_dict and isinstance(state_dict["state_dict"], Mapping):
        state_dict = state_dict["state_dict"]
    prefixed = {k[len("generator.") :]: v for k, v in state_dict.items() if k.startswith("generator.")}
    if prefixed:
        return prefixed
    bare = {k: v for k, v in state_dict.items() if k.startswith("model.")}
    if not bare:
        raise ValueError("no generator weights found: expected keys 'generator.model.*' or 'model.*'")
    return bare


def adapt_first_conv(weight: torch.Tensor, in_channels: int) -> torch.Tensor:
    """Official (out, 4, k, k) weights for [R, G, B, mask] -> ours for [grey image, mask].

    Our grey image stands for R = G = B, so the sum of the three colour kernels gives the
    same response the official conv gives to that grey image; the mask kernel is kept.
    """
    if weight.shape[1] == in_channels:
        return weight
    if weight.shape[1] == 4 and in_channels == 2:
        return torch.cat([weight[:, :3].sum(dim=1, keepdim=True), weight[:, 3:4]], dim=1)
    raise ValueError(f"cannot adapt a first convolution with {weight.shape[1]} input channels to {in_channels}")


def adapt_last_conv(weight: torch.Tensor, bias: Optional[torch.Tensor], out_channels: int):
    """Official (3, ngf, k, k) RGB output conv -> ours: the mean of the colour kernels (grey logit)."""
    if weight.shape[0] == out_channels:
        return weight, bias
    if out_channels == 1:
        return weight.mean(dim=0, keepdim=True), None if bias is None else bias.mean(dim=0, keepdim=True)
    raise ValueError(f"cannot adapt a last convolution with {weight.shape[0]} outputs to {out_channels}")


def load_big_lama_generator(model: InpainterModel, state_dict: Mapping[str, torch.Tensor], strict: bool = True) -> dict:
    """Load official (Big-)LaMa generator weights into `model`, adapting its first and last conv.

    `state_dict` may be a whole LaMa checkpoint (`{"state_dict": {"generator.model...": ...,
    "discriminator...": ...}}`), its `state_dict`, or bare generator keys. Returns a
    summary {loaded, adapted}; raises with the offending keys when the layouts differ.
    """
    weights = generator_state_dict(state_dict)
    weights = dict(weights)
    adapted = []
    if FIRST_CONV in weights:
        new = adapt_first_conv(weights[FIRST_CONV], model.config.in_channels)
        if new is not weights[FIRST_CONV]:
            adapted.append(FIRST_CONV)
        weights[FIRST_CONV] = new
    last = last_conv_prefix(model)
    if f"{last}.weight" in weights:
        w, b = adapt_last_conv(weights[f"{last}.weight"], weights.get(f"{last}.bias"), model.config.out_channels)
        if w is not weights[f"{last}.weight"]:
            adapted += [f"{last}.weight", f"{last}.bias"]
        weights[f"{last}.weight"] = w
        if b is not None:
            weights[f"{last}.bias"] = b
    own = model.state_dict()
    mismatched = [
        f"{k}: checkpoint {tuple(v.shape)} vs model {tuple(own[k].shape)}"
        for k, v in weights.items()
        if k in own and tuple(v.shape) != tuple(own[k].shape)
    ]
    if mismatched:
        raise ValueError(
            "generator weights do not fit this layout (use InpainterConfig.big_lama()):\n  "
            + "\n  ".join(mismatched[:10])
        )
    result = model.load_state_dict(weights, strict=strict)
    return {
        "loaded": len(weights),
        "adapted": adapted,
        "missing": list(result.missing_keys),
        "unexpected": list(result.unexpected_keys),
    }
