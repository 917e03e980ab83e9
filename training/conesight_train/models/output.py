"""What a keypoint network returns."""

from __future__ import annotations

from typing import NamedTuple

import torch


class KeypointOutput(NamedTuple):
    """Keypoints `[N, 7, 2]` (x, y) in patch pixels, and for networks that estimate it the
    expected error per keypoint `sigma_px [N, 7]` (PnP weight 1 / sigma^2), else None."""

    keypoints_px: torch.Tensor
    sigma_px: torch.Tensor | None = None
    heatmaps: torch.Tensor | None = None  # softmax-normalised [N, 7, h, w], training only
