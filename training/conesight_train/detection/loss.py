"""Detector loss: CenterNet's focal loss on the heatmaps, L1 on log sizes and offsets."""

from __future__ import annotations

from dataclasses import dataclass

import torch

SIZE_WEIGHT = 1.0
OFFSET_WEIGHT = 1.0
FOCAL_ALPHA = 2.0
FOCAL_BETA = 4.0


@dataclass(frozen=True)
class DetectionLoss:
    """The total and its parts."""

    total: torch.Tensor
    heat: torch.Tensor
    size: torch.Tensor
    offset: torch.Tensor


def focal_loss(logits: torch.Tensor, target: torch.Tensor) -> torch.Tensor:
    """CenterNet's penalty-reduced focal loss, normalised by the number of peaks."""
    p = torch.sigmoid(logits).clamp(1e-4, 1 - 1e-4)
    positive = target.eq(1.0).to(p.dtype)
    pos_loss = -torch.log(p) * (1 - p) ** FOCAL_ALPHA * positive
    neg_loss = -torch.log(1 - p) * p**FOCAL_ALPHA * (1 - target) ** FOCAL_BETA * (1 - positive)
    return (pos_loss.sum() + neg_loss.sum()) / positive.sum().clamp_min(1.0)


def detection_loss(
    heat_logits: torch.Tensor,
    regression: torch.Tensor,
    heat: torch.Tensor,
    index: torch.Tensor,
    mask: torch.Tensor,
    log_size: torch.Tensor,
    offset: torch.Tensor,
) -> DetectionLoss:
    """Batched targets as stacked `DetectionTargets` fields (see `targets.py`)."""
    n = regression.shape[0]
    reg = regression.reshape(n, 4, -1)
    gathered = torch.gather(reg, 2, index.unsqueeze(1).expand(n, 4, index.shape[1]))
    gathered = gathered.permute(0, 2, 1)  # [N, K, 4]
    weight = mask.unsqueeze(-1)
    count = mask.sum().clamp_min(1.0)
    size = (torch.abs(gathered[..., :2] - log_size) * weight).sum() / count
    off = (torch.abs(gathered[..., 2:] - offset) * weight).sum() / count
    heat_term = focal_loss(heat_logits, heat)
    total = heat_term + SIZE_WEIGHT * size + OFFSET_WEIGHT * off
    return DetectionLoss(total, heat_term, size, off)
