"""Keypoint networks. Both take float32 [N, 3, 80, 80] RGB 0..255 (see `preprocess.py`) and
return `KeypointOutput` with keypoints in patch pixels (OpenCV convention).

- `baseline.PaperKeypointNet`: the paper's network (conv-BN-ReLU, 4 basic residual blocks of
  64/128/256/512 channels, a fully connected layer to 14 numbers).
- `production.HeatmapKeypointNet`: a narrow residual encoder-decoder with per-keypoint heatmaps,
  soft-argmax (integral regression) and a per-keypoint error scale `sigma_px`.

`build_model(name)` makes either by name ("baseline", "production").
"""

from __future__ import annotations

from typing import Any

from torch import nn

from conesight_train.models.baseline import PaperKeypointNet
from conesight_train.models.output import KeypointOutput
from conesight_train.models.production import HeatmapKeypointNet, HeatmapNetParams

MODEL_NAMES: tuple[str, ...] = ("baseline", "production")


def build_model(name: str, **kwargs: Any) -> nn.Module:
    """The keypoint network called `name` (one of `MODEL_NAMES`)."""
    if name == "baseline":
        return PaperKeypointNet(**kwargs)
    if name == "production":
        return HeatmapKeypointNet(HeatmapNetParams(**kwargs))
    raise ValueError(f"unknown model {name!r}; expected one of {MODEL_NAMES}")


__all__ = [
    "MODEL_NAMES",
    "HeatmapKeypointNet",
    "HeatmapNetParams",
    "KeypointOutput",
    "PaperKeypointNet",
    "build_model",
]
