"""Small settings the detector tests share: a tiny network, a small input and crop, and a
run config of a few steps around them."""

from __future__ import annotations

from pathlib import Path

from conesight_train.detector.augment import DetectorAugmentParams
from conesight_train.detector.config import SourceSpec, TrainConfig
from conesight_train.detector.frame_input import FrameInputParams
from conesight_train.detector.model import DetectorParams

TINY = DetectorParams(
    stem_channels=8, stage_channels=(16, 16, 24, 32), stage_blocks=(1, 1, 1, 1), neck_channels=16
)
SMALL_INPUT = FrameInputParams(input_width_px=128, input_height_px=96)
SMALL_CROP = DetectorAugmentParams(crop_width_px=96, crop_height_px=64)


def tiny_run(source: str, val: str, out: Path, **overrides: object) -> TrainConfig:
    """A run of 2 steps at batch 2 on `source`, validated on `val`, into `out`."""
    settings: dict[str, object] = {
        "sources": [SourceSpec(source)],
        "val": val,
        "out": str(out),
        "steps": 2,
        "batch_size": 2,
        "val_every": 2,
        "warmup_steps": 1,
        "workers": 0,
        "input": SMALL_INPUT,
        "augment": SMALL_CROP,
        "model": TINY,
    }
    settings.update(overrides)
    return TrainConfig(**settings)  # type: ignore[arg-type]
