"""What the inpainter is trained and judged by: the hole and known-pixel BCE, precision / recall /
F1 of the predicted free nodes, and the conditional PatchGAN discriminator of the optional
adversarial loss (LaMa's, with an R1 penalty)."""

from __future__ import annotations

from typing import Sequence

import torch
import torch.nn as nn
import torch.nn.functional as F

from pipeline.models.modeling_inpainter import PIXEL_FREE_MIN, PIXEL_OBSTACLE_MAX, InpainterModel
from pipeline.training.inpainter_data import PairSet


# ----------------------------------------------------------------------------- masks, loss, metrics
def unknown_mask(observed: torch.Tensor) -> torch.Tensor:
    return (observed > PIXEL_OBSTACLE_MAX) & (observed < PIXEL_FREE_MIN)


def hole_and_known(observed: torch.Tensor, valid: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(hole, known) boolean masks: unknown / known pixels inside the lattice (padding in neither)."""
    valid = valid.bool()
    unknown = unknown_mask(observed)
    return unknown & valid, ~unknown & valid


def as_image_batch(x: torch.Tensor) -> torch.Tensor:
    return x.unsqueeze(1) if x.dim() == 3 else x


def inpainting_loss(
    logits: torch.Tensor,
    observed: torch.Tensor,
    target: torch.Tensor,
    valid: torch.Tensor,
    known_weight: float = 0.1,
    hole_pos_weight: float = 1.0,
) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
    """BCE over hole pixels + known_weight * BCE over known pixels; invalid (padding) pixels ignored.

    All arguments are (B, 1, H, W) or (B, H, W); `target` is a node image (255 free).
    Returns (loss, {"hole": ..., "known": ...}).
    """
    logits, observed, target, valid = (as_image_batch(t) for t in (logits, observed, target, valid))
    hole, known = hole_and_known(observed, valid)
    free = (target >= PIXEL_FREE_MIN).to(logits.dtype)
    weight = torch.where(free > 0, torch.full_like(free, hole_pos_weight), torch.ones_like(free))
    bce = F.binary_cross_entropy_with_logits(logits, free, reduction="none")
    zero = torch.zeros((), dtype=bce.dtype, device=bce.device)
    hole_loss = torch.where(hole, bce * weight, zero).sum() / hole.sum().clamp_min(1)
    known_loss = torch.where(known, bce, zero).sum() / known.sum().clamp_min(1)
    return hole_loss + known_weight * known_loss, {"hole": hole_loss.detach(), "known": known_loss.detach()}


def hole_counts(
    probs: torch.Tensor, observed: torch.Tensor, target: torch.Tensor, valid: torch.Tensor, threshold: float
) -> torch.Tensor:
    """[true positives, false positives, false negatives] of predicted free nodes in the hole."""
    probs, observed, target, valid = (as_image_batch(t) for t in (probs, observed, target, valid))
    hole, _ = hole_and_known(observed, valid)
    predicted = (probs >= threshold) & hole
    actual = (target >= PIXEL_FREE_MIN) & hole
    return torch.stack([(predicted & actual).sum(), (predicted & ~actual).sum(), (~predicted & actual).sum()]).double()


def precision_recall_f1(counts: Sequence[float]) -> dict[str, float]:
    tp, fp, fn = (float(c) for c in counts[:3])
    precision = tp / (tp + fp) if tp + fp else 0.0
    recall = tp / (tp + fn) if tp + fn else 0.0
    f1 = 2 * precision * recall / (precision + recall) if precision + recall else 0.0
    return {"precision": precision, "recall": recall, "f1": f1, "predicted": int(tp + fp), "actual": int(tp + fn)}


@torch.inference_mode()
def evaluate_inpainter(
    model: InpainterModel, pairs: PairSet, thresholds: Sequence[float] = (0.5,), batch_size: int = 64
) -> dict[float, dict[str, float]]:
    """Hole precision / recall / F1 of a model (in eval mode) on a pair set, per threshold."""
    counts = {t: torch.zeros(3, dtype=torch.float64) for t in thresholds}
    for group in pairs.values():
        for start in range(0, len(group["observed"]), batch_size):
            observed = torch.from_numpy(group["observed"][start : start + batch_size])
            target = torch.from_numpy(group["target"][start : start + batch_size])
            valid = torch.from_numpy(group["valid"][start : start + batch_size])
            probs = model(observed.unsqueeze(1)).float().cpu()
            for t in thresholds:
                counts[t] += hole_counts(probs, observed, target, valid, t)
    return {t: precision_recall_f1(c.tolist()) for t, c in counts.items()}


# ----------------------------------------------------------------------------- discriminator
class PatchDiscriminator(nn.Module):
    """A small conditional PatchGAN: [net input channels, free-node image in [-1, 1]] -> patch logits."""

    def __init__(self, in_channels: int, width: int = 32) -> None:
        super().__init__()
        self.net = nn.Sequential(
            nn.Conv2d(in_channels, width, 4, stride=2, padding=1),
            nn.LeakyReLU(0.2),
            nn.Conv2d(width, width * 2, 4, stride=2, padding=1),
            nn.LeakyReLU(0.2),
            nn.Conv2d(width * 2, width * 2, 3, padding=1),
            nn.LeakyReLU(0.2),
            nn.Conv2d(width * 2, 1, 3, padding=1),
        )

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)
