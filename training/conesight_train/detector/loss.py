"""Detector loss: CenterNet's penalty-reduced focal loss on the heatmaps, and box regression
(offsets, log height, log aspect): L1 at the object centres (CenterNet), or with
`LossParams.dense` L1 and GIoU over each object's dense-regression cells (TTFNet; see
`targets.py`), each object weighing 1."""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch

from conesight_train.detector.model import decode_boxes

FOCAL_ALPHA = 2.0
FOCAL_BETA = 4.0


@dataclass(frozen=True)
class LossParams:
    """Weights of the loss terms (defaults: the first runs' CenterNet loss)."""

    regression_weight: float = 1.0
    dense: bool = False
    giou_weight: float = 0.0

    def to_dict(self) -> dict[str, object]:
        """The fields for checkpoints and cards."""
        return asdict(self)


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


def giou(boxes: torch.Tensor, targets: torch.Tensor) -> torch.Tensor:
    """Generalised IoU of (cx, cy, w, h) boxes [N, 4, ...] against targets of the same shape."""

    def corners(b: torch.Tensor) -> tuple[torch.Tensor, ...]:
        return (
            b[:, 0] - b[:, 2] / 2,
            b[:, 1] - b[:, 3] / 2,
            b[:, 0] + b[:, 2] / 2,
            b[:, 1] + b[:, 3] / 2,
        )

    ax0, ay0, ax1, ay1 = corners(boxes)
    bx0, by0, bx1, by1 = corners(targets)
    iw = (torch.minimum(ax1, bx1) - torch.maximum(ax0, bx0)).clamp_min(0)
    ih = (torch.minimum(ay1, by1) - torch.maximum(ay0, by0)).clamp_min(0)
    inter = iw * ih
    union = boxes[:, 2] * boxes[:, 3] + targets[:, 2] * targets[:, 3] - inter
    iou = inter / union.clamp_min(1e-9)
    hull = (torch.maximum(ax1, bx1) - torch.minimum(ax0, bx0)) * (
        torch.maximum(ay1, by1) - torch.minimum(ay0, by0)
    )
    return iou - (hull - union) / hull.clamp_min(1e-9)


def detector_loss(
    heat_logits: torch.Tensor,
    regression: torch.Tensor,
    targets: dict[str, torch.Tensor],
    params: LossParams | None = None,
) -> DetectorLoss:
    """Loss of a batch; `targets` holds the stacked `DetectorTargets` fields."""
    p = params or LossParams()
    heat = focal_loss(heat_logits, targets["heat"], targets["ignore"])
    if p.dense:
        weight = targets["dense_weight"]
        objects = weight.sum().clamp_min(1.0)
        dense = targets["dense_regression"]
        l1 = (torch.abs(regression - dense).sum(1) * weight).sum() / objects
        reg = p.regression_weight * l1
        if p.giou_weight > 0:
            owned = weight > 0
            g = giou(decode_boxes(regression), decode_boxes(dense))
            reg = reg + p.giou_weight * ((1 - g) * weight * owned).sum() / objects
        return DetectorLoss(heat + reg, heat, reg)
    n = regression.shape[0]
    index = targets["index"]
    gathered = torch.gather(
        regression.reshape(n, 4, -1), 2, index.unsqueeze(1).expand(n, 4, index.shape[1])
    ).permute(0, 2, 1)
    mask = targets["mask"].unsqueeze(-1)
    reg = (torch.abs(gathered - targets["regression"]) * mask).sum() / mask.sum().clamp_min(1.0)
    reg = p.regression_weight * reg
    return DetectorLoss(heat + reg, heat, reg)
