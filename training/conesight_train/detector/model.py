"""The cone detector: a light residual/separable encoder to stride 32, a top-down path to
stride 4, and CenterNet-style heads with a tall box prior.

Input: float32 [N, 3, H, W] RGB, raw 0..255 (the band of `band.py`), H and W multiples of 32.
`forward` returns (heat_logits [N, C, H/4, W/4], regression [N, 4, H/4, W/4]) where the
regression channels are (dx, dy, log_h, log_aspect) per cell:

    centre = (cell + 0.5 + (dx, dy)) * STRIDE_PX        (continuous input pixels)
    height = exp(log_h) * STRIDE_PX
    width  = height * ASPECT_PRIOR * exp(log_aspect)

ASPECT_PRIOR (width / height) is the box prior: cones are taller than wide (small cone
228 x 325 mm, large 285 x 505 mm; boxes with the base plate 0.4-0.95, median ~0.7), so an
untrained or uncertain head still predicts tall boxes, and the heatmap targets are Gaussians
elongated the same way (`targets.py`).

Size head (`DetectorParams.size_head`): orange and large orange cones differ mainly in size
(505 vs 325 mm; two stripes instead of one), and large ones are ~3 % of the cones, so with a
heatmap each they split their evidence and the rare class stays weak. With the size head the
heatmaps are blue, yellow and *orange-family* (both orange classes), and a fifth regression
channel is a "large" logit, predicted from the features, the cell's predicted box height
(log_h, detached) and its row: on flat ground a cone's pixel height over its base row's
distance below the horizon is its height over the camera's, which tells 505 from 325 mm for
any mount of 0.75-1.25 m except a narrow overlap. The export splits the family's score
into orange = heat (1 - p_large) and large orange = heat p_large, so the output layout and
the decoder are unchanged.

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
    # Rows as a feature: (y, y^2) of each stride-4 cell, through a 1x1 conv, added to the
    # finest features before the heads. The band starts a fixed distance above the horizon, so
    # the row says how far a cone standing there is and so how tall it should be: the cue
    # that tells a large orange cone from a near small one.
    row_features: bool = False
    # Orange-family heatmap + a "large" logit instead of two orange heatmaps (module docs).
    size_head: bool = False

    @property
    def heat_channels(self) -> int:
        """Heatmaps the network outputs: the classes, or 3 with the size head."""
        return self.class_count - 1 if self.size_head else self.class_count

    def to_dict(self) -> dict[str, object]:
        """Keyword arguments that rebuild these params (for checkpoints and cards)."""
        d = asdict(self)
        d["stage_channels"] = list(self.stage_channels)
        d["stage_blocks"] = list(self.stage_blocks)
        return d

    @staticmethod
    def from_dict(d: dict[str, object]) -> DetectorParams:
        """Inverse of `to_dict`."""
        return DetectorParams(
            class_count=int(d["class_count"]),  # type: ignore[arg-type]
            stem_channels=int(d["stem_channels"]),  # type: ignore[arg-type]
            stage_channels=tuple(d["stage_channels"]),  # type: ignore[arg-type]
            stage_blocks=tuple(d["stage_blocks"]),  # type: ignore[arg-type]
            neck_channels=int(d["neck_channels"]),  # type: ignore[arg-type]
            row_features=bool(d.get("row_features", False)),
            size_head=bool(d.get("size_head", False)),
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
        self.row_embed = nn.Conv2d(2, d, 1) if p.row_features else None
        if p.size_head and p.class_count != len(CLASS_NAMES):
            raise ValueError("the size head needs the 4 cone classes (the last two orange)")
        self.heat_head = _separable_head(d, p.heat_channels)
        self.reg_head = _separable_head(d, 4)
        # Size head: features + (log_h, y, y^2) -> "large" logit (module docs).
        self.size_head = (
            nn.Sequential(
                nn.Conv2d(d + 3, d, 1),
                nn.ReLU(inplace=True),
                nn.Conv2d(d, d, 3, 1, 1, groups=d),
                nn.ReLU(inplace=True),
                nn.Conv2d(d, 1, 1),
            )
            if p.size_head
            else None
        )
        init_weights(self)
        heat_out = self.heat_head[-1]
        reg_out = self.reg_head[-1]
        if isinstance(heat_out, nn.Conv2d) and heat_out.bias is not None:
            # Small weights (RetinaNet's 0.01): every cell starts at the prior, whatever the
            # image; He init here gave logits up to +30 on rendered frames and a loss of ~600.
            nn.init.normal_(heat_out.weight, 0.0, 0.01)
            nn.init.constant_(heat_out.bias, HEAT_BIAS_INIT)
        if self.size_head is not None:
            size_out = self.size_head[-1]
            if isinstance(size_out, nn.Conv2d) and size_out.bias is not None:
                nn.init.normal_(size_out.weight, 0.0, 0.01)
                nn.init.zeros_(size_out.bias)
        if isinstance(reg_out, nn.Conv2d) and reg_out.bias is not None:
            nn.init.normal_(reg_out.weight, 0.0, 0.01)
            with torch.no_grad():
                reg_out.bias.copy_(torch.tensor([0.0, 0.0, LOG_H_BIAS_INIT, 0.0]))

    def forward(self, x: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """(heat_logits [N, heat_channels, h, w], regression [N, 4 (+1 large logit), h, w])."""
        f4 = self.stage4(self.stem(self.normalise(x)))
        f8 = self.stage8(f4)
        f16 = self.stage16(f8)
        f32 = self.stage32(f16)
        p16 = self.smooth16(F.interpolate(self.lat32(f32), scale_factor=2.0) + self.lat16(f16))
        p8 = self.smooth8(F.interpolate(p16, scale_factor=2.0) + self.lat8(f8))
        p4 = self.smooth4(F.interpolate(p8, scale_factor=2.0) + self.lat4(f4))
        h = p4.shape[2]
        y = (torch.arange(h, dtype=p4.dtype, device=p4.device) + 0.5) / h
        rows = torch.stack([y, y * y]).view(1, 2, h, 1).expand(p4.shape[0], 2, h, p4.shape[3])
        if self.row_embed is not None:
            p4 = p4 + self.row_embed(rows)
        heat, reg = self.heat_head(p4), self.reg_head(p4)
        if self.size_head is not None:
            cues = torch.cat([p4, reg[:, 2:3].detach(), rows], dim=1)
            reg = torch.cat([reg, self.size_head(cues)], dim=1)
        return heat, reg


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


def peak_scores(heat_logits: torch.Tensor, regression: torch.Tensor | None = None) -> torch.Tensor:
    """Class scores [N, C, h, w]: sigmoid(heat), zero except at 3x3 local maxima of each map;
    with the size head (`heat_logits` of 3 maps, pass its 5-channel `regression`), the
    orange-family peaks are split into orange and large orange by p_large (module docs)."""
    heat = torch.sigmoid(heat_logits)
    keep = (F.max_pool2d(heat, 3, stride=1, padding=1) == heat).to(heat.dtype)
    peaks = heat * keep
    if regression is None:
        return peaks
    p_large = torch.sigmoid(regression[:, 4:5])
    family = peaks[:, 2:3]
    return torch.cat([peaks[:, :2], family * (1 - p_large), family * p_large], dim=1)


class ExportHead(nn.Module):
    """The detector followed by box decoding and peak scores: [N, 4 + C, h * w] (see docs)."""

    def __init__(self, detector: ConeDetector) -> None:
        super().__init__()
        self.detector = detector

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        heat, reg = self.detector(x)
        boxes = decode_boxes(reg[:, :4])
        scores = peak_scores(heat, reg if self.detector.size_head is not None else None)
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
