"""The cone detector: a light residual/separable encoder to stride 32, a top-down path to
stride 4, and CenterNet-style heads with a tall box prior.

Input: float32 [N, 3, H, W] RGB, raw 0..255 (the whole frame, `frame_input.py`; training takes
crops of any size), H and W multiples of 32. Nothing in the network depends on the row, so a
cone looks the same to it wherever it stands in the frame: a pitched camera, a different mount
or a bump moves cones in the image, not out of the detector's view.
`forward` returns (heat_logits [N, C, H/4, W/4], regression [N, 4, H/4, W/4]) where the
regression channels are (dx, dy, log_h, log_aspect) per cell:

    centre = (cell + 0.5 + (dx, dy)) * STRIDE_PX        (continuous input pixels)
    height = exp(log_h) * STRIDE_PX
    width  = height * ASPECT_PRIOR * exp(log_aspect)

ASPECT_PRIOR (width / height) is the box prior: cones are taller than wide (small cone
228 x 325 mm, large 285 x 505 mm; boxes with the base plate 0.4-0.95, median ~0.7), so an
untrained or uncertain head still predicts tall boxes, and the heatmap targets are Gaussians
elongated the same way (`targets.py`).

`ExportHead` wraps the network for ONNX: one output `detections [N, 4 + C, H/4 * W/4]`, the
Ultralytics layout (cx, cy, w, h in continuous input pixels, then per-class scores). Scores are
sigmoid(heat) kept only at 3x3 local maxima (CenterNet peaks), so the shared Rust decoder
(threshold, class-aware NMS) sees one candidate per cone.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import torch
import torch.nn.functional as F
from torch import nn

from conesight_train.models.blocks import ConvBNReLU, Normalise, init_weights

STRIDE_PX = 4
# Box width / height at zero output: the median of rendered cone boxes (0.66 and 0.77 in two
# renderer outputs, 224 boxes; near cones show their base plate, ~0.85-0.9).
ASPECT_PRIOR = 0.75
# sigmoid(-4.6) = 0.01: rare positives, CenterNet/RetinaNet prior for stable early training.
HEAT_BIAS_INIT = -4.6
# exp(2.0) * 4 = 30 px: a typical cone height in input pixels at initialisation.
LOG_H_BIAS_INIT = 2.0
CLASS_NAMES: tuple[str, ...] = ("blue", "yellow", "orange", "large_orange")


@dataclass(frozen=True)
class DetectorParams:
    """Widths of the detector (defaults: the shipped configuration)."""

    class_count: int = len(CLASS_NAMES)
    stem_channels: int = 16  # stride 2
    stage_channels: tuple[int, int, int, int] = (24, 48, 64, 96)  # strides 4, 8, 16, 32
    stage_blocks: tuple[int, int, int, int] = (1, 2, 2, 2)
    neck_channels: int = 32

    def to_dict(self) -> dict[str, object]:
        """Keyword arguments that rebuild these params (for checkpoints and cards)."""
        d = asdict(self)
        d["stage_channels"] = list(self.stage_channels)
        d["stage_blocks"] = list(self.stage_blocks)
        return d

    @staticmethod
    def from_dict(d: dict[str, object]) -> DetectorParams:
        """Inverse of `to_dict`."""
        known = {"class_count", "stem_channels", "stage_channels", "stage_blocks", "neck_channels"}
        unknown = set(d) - known
        if unknown:
            raise ValueError(
                f"detector model settings {sorted(unknown)} are not supported (row features and "
                "the size head belonged to the horizon-band detector); known: "
                f"{sorted(known)}"
            )
        return DetectorParams(
            class_count=int(d["class_count"]),  # type: ignore[arg-type]
            stem_channels=int(d["stem_channels"]),  # type: ignore[arg-type]
            stage_channels=tuple(d["stage_channels"]),  # type: ignore[arg-type]
            stage_blocks=tuple(d["stage_blocks"]),  # type: ignore[arg-type]
            neck_channels=int(d["neck_channels"]),  # type: ignore[arg-type]
        )


class SeparableBlock(nn.Module):
    """Depthwise 3x3 (stride s) - BN - ReLU - pointwise 1x1 - BN, residual when shapes match."""

    def __init__(self, c_in: int, c_out: int, stride: int = 1) -> None:
        super().__init__()
        self.depthwise = nn.Sequential(
            nn.Conv2d(c_in, c_in, 3, stride, 1, groups=c_in, bias=False),
            nn.BatchNorm2d(c_in),
            nn.ReLU(inplace=True),
        )
        self.pointwise = nn.Sequential(nn.Conv2d(c_in, c_out, 1, bias=False), nn.BatchNorm2d(c_out))
        self.residual = stride == 1 and c_in == c_out
        self.relu = nn.ReLU(inplace=True)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        out = self.pointwise(self.depthwise(x))
        return self.relu(out + x if self.residual else out)


def _stage(c_in: int, c_out: int, blocks: int) -> nn.Sequential:
    layers: list[nn.Module] = [SeparableBlock(c_in, c_out, stride=2)]
    layers += [SeparableBlock(c_out, c_out) for _ in range(blocks - 1)]
    return nn.Sequential(*layers)


def _separable_head(channels: int, out: int) -> nn.Sequential:
    return nn.Sequential(
        nn.Conv2d(channels, channels, 3, 1, 1, groups=channels, bias=False),
        nn.BatchNorm2d(channels),
        nn.ReLU(inplace=True),
        nn.Conv2d(channels, out, 1),
    )


class ConeDetector(nn.Module):
    """See the module docs."""

    def __init__(self, params: DetectorParams | None = None) -> None:
        super().__init__()
        p = params or DetectorParams()
        self.params = p
        c4, c8, c16, c32 = p.stage_channels
        d = p.neck_channels
        self.normalise = Normalise()
        # Full convolutions while channels are few (cheap, and better than depthwise at 3 in).
        self.stem = ConvBNReLU(3, p.stem_channels, stride=2)
        self.stage4 = nn.Sequential(
            ConvBNReLU(p.stem_channels, c4, stride=2),
            *[SeparableBlock(c4, c4) for _ in range(p.stage_blocks[0])],
        )
        self.stage8 = _stage(c4, c8, p.stage_blocks[1])
        self.stage16 = _stage(c8, c16, p.stage_blocks[2])
        self.stage32 = _stage(c16, c32, p.stage_blocks[3])
        self.lat32 = nn.Conv2d(c32, d, 1)
        self.lat16 = nn.Conv2d(c16, d, 1)
        self.lat8 = nn.Conv2d(c8, d, 1)
        self.lat4 = nn.Conv2d(c4, d, 1)
        self.smooth16 = SeparableBlock(d, d)
        self.smooth8 = SeparableBlock(d, d)
        self.smooth4 = SeparableBlock(d, d)
        self.heat_head = _separable_head(d, p.class_count)
        self.reg_head = _separable_head(d, 4)
        init_weights(self)
        heat_out = self.heat_head[-1]
        reg_out = self.reg_head[-1]
        if isinstance(heat_out, nn.Conv2d) and heat_out.bias is not None:
            # Small weights (RetinaNet's 0.01): every cell starts at the prior, whatever the
            # image; He init here gave logits up to +30 on rendered frames and a loss of ~600.
            nn.init.normal_(heat_out.weight, 0.0, 0.01)
            nn.init.constant_(heat_out.bias, HEAT_BIAS_INIT)
        if isinstance(reg_out, nn.Conv2d) and reg_out.bias is not None:
            nn.init.normal_(reg_out.weight, 0.0, 0.01)
            with torch.no_grad():
                reg_out.bias.copy_(torch.tensor([0.0, 0.0, LOG_H_BIAS_INIT, 0.0]))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(heat_logits [N, classes, h, w], regression [N, 4, h, w])."""
        f4 = self.stage4(self.stem(self.normalise(x)))
        f8 = self.stage8(f4)
        f16 = self.stage16(f8)
        f32 = self.stage32(f16)
        p16 = self.smooth16(F.interpolate(self.lat32(f32), scale_factor=2.0) + self.lat16(f16))
        p8 = self.smooth8(F.interpolate(p16, scale_factor=2.0) + self.lat8(f8))
        p4 = self.smooth4(F.interpolate(p8, scale_factor=2.0) + self.lat4(f4))
        return self.heat_head(p4), self.reg_head(p4)


def decode_boxes(regression: torch.Tensor) -> torch.Tensor:
    """Regression [N, 4, h, w] -> boxes [N, 4, h, w] (cx, cy, w, h; continuous input px)."""
    _, _, h, w = regression.shape
    ys = torch.arange(h, dtype=regression.dtype, device=regression.device).view(1, h, 1)
    xs = torch.arange(w, dtype=regression.dtype, device=regression.device).view(1, 1, w)
    cx = (xs + 0.5 + regression[:, 0]) * STRIDE_PX
    cy = (ys + 0.5 + regression[:, 1]) * STRIDE_PX
    height = torch.exp(regression[:, 2].clamp(max=8.0)) * STRIDE_PX
    width = height * ASPECT_PRIOR * torch.exp(regression[:, 3].clamp(-3.0, 3.0))
    return torch.stack([cx, cy, width, height], dim=1)


def peak_scores(heat_logits: torch.Tensor) -> torch.Tensor:
    """Class scores [N, C, h, w]: sigmoid(heat), zero except at 3x3 local maxima of each map."""
    heat = torch.sigmoid(heat_logits)
    keep = (F.max_pool2d(heat, 3, stride=1, padding=1) == heat).to(heat.dtype)
    return heat * keep


class ExportHead(nn.Module):
    """The detector followed by box decoding and peak scores: [N, 4 + C, h * w] (see docs)."""

    def __init__(self, detector: ConeDetector) -> None:
        super().__init__()
        self.detector = detector

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        heat, reg = self.detector(x)
        boxes = decode_boxes(reg)
        scores = peak_scores(heat)
        n = x.shape[0]
        return (
            torch.cat([boxes, scores], dim=1)
            .flatten(2)
            .reshape(n, -1, boxes.shape[2] * boxes.shape[3])
        )


def multiply_accumulates(model: nn.Module, input_hw: tuple[int, int]) -> int:
    """Multiply-accumulates of the convolutions for one input of `input_hw` (hooks, one pass)."""
    total = 0

    def hook(module: nn.Module, _inputs: tuple[torch.Tensor, ...], output: torch.Tensor) -> None:
        nonlocal total
        if isinstance(module, nn.Conv2d):
            k = module.kernel_size[0] * module.kernel_size[1]
            total += output.numel() * k * module.in_channels // module.groups

    handles = [m.register_forward_hook(hook) for m in model.modules() if isinstance(m, nn.Conv2d)]
    try:
        with torch.no_grad():
            model.eval()(torch.zeros(1, 3, *input_hw))
    finally:
        for h in handles:
            h.remove()
    return total
