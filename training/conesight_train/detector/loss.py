"""Detector loss: CenterNet's penalty-reduced focal loss on the heatmaps, L1 on the regression
(offsets, log height, log aspect) at the object centres."""

from __future__ import annotations

from dataclasses import dataclass

import torch

REGRESSION_WEIGHT = 1.0
FOCAL_ALPHA = 2.0
FOCAL_BETA = 4.0


@dataclass(frozen=True)
class DetectorLoss:
    """The total and its parts."""

    total: torch.Tensor
    heat: torch.Tensor
    regression: torch.Tensor


def focal_loss(logits: torch.Tensor, target: torch.Tensor, ignore: torch.Tensor) -> torch.Tensor:
    """Focal loss [N, C, h, w] against Gaussian targets; `ignore` [N, h, w] masks negatives."""
    log_p = torch.nn.functional.logsigmoid(logits)
    log_not_p = torch.nn.functional.logsigmoid(-logits)
    p = torch.sigmoid(logits)
    positive = target.eq(1.0).to(p.dtype)
    negative_weight = (1 - positive) * (1 - ignore.unsqueeze(1))
    pos = -log_p * (1 - p) ** FOCAL_ALPHA * positive
    neg = -log_not_p * p**FOCAL_ALPHA * (1 - target) ** FOCAL_BETA * negative_weight
    return (pos.sum() + neg.sum()) / positive.sum().clamp_min(1.0)


def detector_loss(
    heat_logits: torch.Tensor, regression: torch.Tensor, targets: dict[str, torch.Tensor]
) -> DetectorLoss:
    """Loss of a batch; `targets` holds the stacked `DetectorTargets` fields."""
    n = regression.shape[0]
    index = targets["index"]
    gathered = torch.gather(
        regression.reshape(n, 4, -1), 2, index.unsqueeze(1).expand(n, 4, index.shape[1])
    ).permute(0, 2, 1)
    mask = targets["mask"].unsqueeze(-1)
    reg = (torch.abs(gathered - targets["regression"]) * mask).sum() / mask.sum().clamp_min(1.0)
    heat = focal_loss(heat_logits, targets["heat"], targets["ignore"])
    return DetectorLoss(heat + REGRESSION_WEIGHT * reg, heat, reg)
