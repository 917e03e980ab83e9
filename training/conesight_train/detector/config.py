"""Training run settings: a dataclass read from YAML, overridable by CLI flags.

Data sources: a renderer output folder, or `toy:COUNT[:SEED]` for procedural frames (tests and
smoke runs; they need a band that fits their size, e.g. `band: {input_width_px: 128,
input_height_px: 64, factor: 2, band_top_px: 32}` for the default 256x160 toy frames).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from conesight_train.detector.band import BandParams
from conesight_train.detector.data import FrameSource, RendererFrames, ToyFrames
from conesight_train.detector.loss import LossParams
from conesight_train.detector.model import DetectorParams
from conesight_train.detector.postprocess import Thresholds


@dataclass
class TrainConfig:
    """Every setting of a run (defaults: the shipped configuration)."""

    train: str = "out/sim-train"
    # Decoded, box-filtered copy of `train` (detector/cache.py), built on first use; "" reads
    # the PNGs on every step instead (100 ms per frame).
    train_cache: str = ""
    val: str = "out/sim-val"
    out: str = "build/train/detector"
    steps: int = 2000
    batch_size: int = 8
    lr: float = 2e-3
    weight_decay: float = 1e-4
    warmup_steps: int = 100
    seed: int = 0
    threads: int = 1
    workers: int = 1
    val_every: int = 250
    val_limit: int = 100
    # Repeat-factor sampling threshold t (detector/sampling.py); 0 = every frame once per epoch.
    repeat_factor_threshold: float = 0.0
    band: BandParams = field(default_factory=BandParams)
    model: DetectorParams = field(default_factory=DetectorParams)
    thresholds: Thresholds = field(default_factory=Thresholds)
    loss: LossParams = field(default_factory=LossParams)

    def to_dict(self) -> dict[str, Any]:
        """Plain data for checkpoints and cards."""
        d = asdict(self)
        d["model"] = self.model.to_dict()
        return d

    @staticmethod
    def from_dict(d: dict[str, Any]) -> TrainConfig:
        """Inverse of `to_dict`; unknown keys are errors naming the key."""
        known = {f.name for f in fields(TrainConfig)}
        unknown = set(d) - known
        if unknown:
            raise ValueError(
                f"unknown detector config keys {sorted(unknown)}; known: {sorted(known)}"
            )
        d = dict(d)
        if "band" in d:
            d["band"] = BandParams(**d["band"])
        if "model" in d:
            d["model"] = DetectorParams.from_dict({**DetectorParams().to_dict(), **d["model"]})
        if "thresholds" in d:
            d["thresholds"] = Thresholds(**d["thresholds"])
        if "loss" in d:
            d["loss"] = LossParams(**d["loss"])
        return TrainConfig(**d)

    @staticmethod
    def from_yaml(path: str | Path) -> TrainConfig:
        """Reads a YAML config file."""
        data = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
        if not isinstance(data, dict):
            raise ValueError(f"{path}: expected a mapping of settings")
        return TrainConfig.from_dict(data)


def open_source(spec: str, limit: int | None = None) -> FrameSource:
    """A renderer folder or `toy:COUNT[:SEED]`."""
    if spec.startswith("toy:"):
        parts = spec.split(":")
        count = int(parts[1])
        seed = int(parts[2]) if len(parts) > 2 else 0
        return ToyFrames(count if limit is None else min(count, limit), seed)
    return RendererFrames(spec, limit)
