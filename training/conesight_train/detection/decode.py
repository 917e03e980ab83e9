"""Detector output -> boxes, in torch ops that export to ONNX.

Peaks are the cells equal to the max of their 3x3 neighbourhood (per class); the top `k` peaks
over all classes become boxes `[x_min, y_min, x_max, y_max, score, class]` in input pixels
(edges, OpenCV convention), inverting `targets.encode`.
"""

from __future__ import annotations

import torch
import torch.nn.functional as F

from conesight_train.detection.targets import STRIDE_PX

TOP_K = 100


def decode(heat_logits: torch.Tensor, regression: torch.Tensor, k: int = TOP_K) -> torch.Tensor:
    """heat_logits [N, C, h, w], regression [N, 4, h, w] (log w, log h, dx, dy) -> [N, k, 6]."""
    n, c, h, w = heat_logits.shape
    heat = torch.sigmoid(heat_logits)
    peaks = heat * (F.max_pool2d(heat, 3, stride=1, padding=1) == heat).to(heat.dtype)
    scores, flat = torch.topk(peaks.reshape(n, c * h * w), k)
    classes = torch.div(flat, h * w, rounding_mode="floor")
    cell = flat - classes * (h * w)
    cy = torch.div(cell, w, rounding_mode="floor")
    cx = cell - cy * w
    reg = regression.reshape(n, 4, h * w)
    gathered = torch.gather(reg, 2, cell.unsqueeze(1).expand(n, 4, k))  # [N, 4, k]
    size_w = torch.exp(gathered[:, 0]) * STRIDE_PX
    size_h = torch.exp(gathered[:, 1]) * STRIDE_PX
    centre_x = (cx.to(heat.dtype) + gathered[:, 2] + 0.5) * STRIDE_PX - 0.5
    centre_y = (cy.to(heat.dtype) + gathered[:, 3] + 0.5) * STRIDE_PX - 0.5
    return torch.stack(
        [
            centre_x - size_w / 2,
            centre_y - size_h / 2,
            centre_x + size_w / 2,
            centre_y + size_h / 2,
            scores,
            classes.to(heat.dtype),
        ],
        dim=-1,
    )
