"""The cone detector: a narrow residual encoder to stride 16, a top-down path to stride 4, and
CenterNet heads (a heatmap per class; log width, log height and centre offset per cell).

Input: float32 [N, 3, H, W] RGB, raw 0..255 (see `detection/frames.py`), H and W multiples of
16. `forward` returns (heat_logits [N, C, H/4, W/4], regression [N, 4, H/4, W/4]);
`DetectorWithDecode` adds the box decoding for export: detections [N, TOP_K, 6].
"""

from __future__ import annotations

from dataclasses import dataclass

import torch
import torch.nn.functional as F
from torch import nn

from conesight_train.data.yolo_txt import CONE_CLASSES
from conesight_train.detection.decode import TOP_K, decode
from conesight_train.models.blocks import BasicBlock, ConvBNReLU, Normalise, init_weights

# Initial heatmap bias: sigmoid(-2.19) = 0.1, CenterNet's prior for stable early training.
HEAT_BIAS_INIT = -2.19


@dataclass(frozen=True)
class DetectorParams:
    """Widths of the detector (defaults are the planned configuration)."""

    class_count: int = len(CONE_CLASSES)
    stem_channels: int = 16
    stage_channels: tuple[int, int, int] = (32, 64, 96)  # strides 4, 8, 16
    neck_channels: int = 48


class ConeDetector(nn.Module):
    """See the module docs."""

    def __init__(self, params: DetectorParams | None = None) -> None:
        super().__init__()
        p = params or DetectorParams()
        self.params = p
        c4, c8, c16 = p.stage_channels
        d = p.neck_channels
        self.normalise = Normalise()
        self.stem = ConvBNReLU(3, p.stem_channels, stride=2)
        self.stage4 = BasicBlock(p.stem_channels, c4, stride=2)
        self.stage8 = BasicBlock(c4, c8, stride=2)
        self.stage16 = nn.Sequential(BasicBlock(c8, c16, stride=2), BasicBlock(c16, c16))
        self.lat16 = nn.Conv2d(c16, d, 1)
        self.lat8 = nn.Conv2d(c8, d, 1)
        self.lat4 = nn.Conv2d(c4, d, 1)
        self.smooth8 = ConvBNReLU(d, d)
        self.smooth4 = ConvBNReLU(d, d)
        self.heat_head = nn.Sequential(ConvBNReLU(d, d), nn.Conv2d(d, p.class_count, 1))
        self.reg_head = nn.Sequential(ConvBNReLU(d, d), nn.Conv2d(d, 4, 1))
        init_weights(self)
        heat_out = self.heat_head[-1]
        assert isinstance(heat_out, nn.Conv2d)
        nn.init.constant_(heat_out.bias, HEAT_BIAS_INIT)

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        f4 = self.stage4(self.stem(self.normalise(x)))
        f8 = self.stage8(f4)
        f16 = self.stage16(f8)
        p8 = self.smooth8(F.interpolate(self.lat16(f16), scale_factor=2.0) + self.lat8(f8))
        p4 = self.smooth4(F.interpolate(p8, scale_factor=2.0) + self.lat4(f4))
        return self.heat_head(p4), self.reg_head(p4)


class DetectorWithDecode(nn.Module):
    """The detector followed by `decode`: [N, TOP_K, 6] boxes in input pixels."""

    def __init__(self, detector: ConeDetector, k: int = TOP_K) -> None:
        super().__init__()
        self.detector = detector
        self.k = k

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        heat, reg = self.detector(x)
        return decode(heat, reg, self.k)
