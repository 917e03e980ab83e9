"""conesight's production keypoint network: narrow, heatmaps + soft-argmax, with sigma_px.

Encoder: conv-BN-ReLU stride 2 (80 -> 40), basic residual blocks at stride 2 (40 -> 20 -> 10)
and one more at 10x10 for context. Decoder: the 10x10 features are upsampled to 20x20 and
added to the 20x20 encoder features (1x1 projections), one 3x3 conv-BN-ReLU, then a 1x1 conv
to 7 heatmaps at 20x20 (stride 4). Soft-argmax (integral regression: the softmax-weighted mean
of the cell centres) gives sub-pixel keypoints; a small head on the pooled 10x10 features
predicts each keypoint's error scale `sigma_px` (trained with a Laplace likelihood on the
detached error, see `losses.py`, then scaled by `sigma_scale` into a per-axis standard
deviation, see `calibrate_sigma.py`), which the PnP uses as a weight 1 / sigma^2.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from conesight_train.keypoints import KEYPOINT_COUNT
from conesight_train.models.blocks import BasicBlock, ConvBNReLU, Normalise, init_weights
from conesight_train.models.output import KeypointOutput

# Smallest sigma the head can report, pixels (keeps 1 / sigma^2 finite).
SIGMA_FLOOR_PX = 0.05
# Patch pixels per heatmap cell (two stride-2 layers: stem and stage 1).
HEATMAP_STRIDE_PX = 4.0


@dataclass(frozen=True)
class HeatmapNetParams:
    """Widths of the production network (defaults are the shipped configuration)."""

    stem_channels: int = 16
    stage_channels: tuple[int, int, int] = (32, 64, 64)
    decoder_channels: int = 32
    # Factor on the sigma head's output, fitted after training on held-out crops so that the
    # exported sigma_px is a calibrated per-axis standard deviation (`calibrate_sigma.py`).
    sigma_scale: float = 1.0


def soft_argmax(logits: torch.Tensor, stride_px: float) -> tuple[torch.Tensor, torch.Tensor]:
    """Softmax over each [h, w] map and its expected cell centre in patch pixels.

    Cell (i, j) of a stride-`s` map covers patch pixels j*s .. j*s + s - 1, whose centres
    average to j*s + (s - 1)/2. Returns (keypoints [N, K, 2] as (x, y), probabilities).
    """
    n, k, h, w = logits.shape
    probs = F.softmax(logits.reshape(n, k, h * w), dim=-1).reshape(n, k, h, w)
    offset = (stride_px - 1.0) / 2.0
    xs = torch.arange(w, dtype=logits.dtype, device=logits.device) * stride_px + offset
    ys = torch.arange(h, dtype=logits.dtype, device=logits.device) * stride_px + offset
    x = (probs.sum(dim=2) * xs).sum(dim=-1)
    y = (probs.sum(dim=3) * ys).sum(dim=-1)
    return torch.stack([x, y], dim=-1), probs


class HeatmapKeypointNet(nn.Module):
    """See the module docs."""

    def __init__(self, params: HeatmapNetParams | None = None) -> None:
        super().__init__()
        p = params or HeatmapNetParams()
        self.params = p
        c1, c2, c3 = p.stage_channels
        d = p.decoder_channels
        self.normalise = Normalise()
        self.stem = ConvBNReLU(3, p.stem_channels, stride=2)  # 40x40
        self.stage1 = BasicBlock(p.stem_channels, c1, stride=2)  # 20x20
        self.stage2 = BasicBlock(c1, c2, stride=2)  # 10x10
        self.stage3 = BasicBlock(c2, c3, stride=1)  # 10x10
        self.top = nn.Conv2d(c3, d, 1)
        self.lateral = nn.Conv2d(c1, d, 1)
        self.fuse = ConvBNReLU(d, d)
        self.heads = nn.Conv2d(d, KEYPOINT_COUNT, 1)
        self.sigma_head = nn.Linear(c3, KEYPOINT_COUNT)
        self.stride_px = HEATMAP_STRIDE_PX
        init_weights(self)

    def forward(self, x: torch.Tensor) -> KeypointOutput:
        x = self.normalise(x)
        f20 = self.stage1(self.stem(x))
        f10 = self.stage3(self.stage2(f20))
        up = F.interpolate(self.top(f10), scale_factor=2.0, mode="nearest")
        fused = self.fuse(up + self.lateral(f20))
        keypoints_px, probs = soft_argmax(self.heads(fused), self.stride_px)
        pooled = torch.flatten(F.adaptive_avg_pool2d(f10, 1), 1)
        sigma_px = (F.softplus(self.sigma_head(pooled)) + SIGMA_FLOOR_PX) * self.params.sigma_scale
        return KeypointOutput(keypoints_px=keypoints_px, sigma_px=sigma_px, heatmaps=probs)
