"""Training run settings: a dataclass read from YAML, overridable by CLI flags.

Data sources (`sources`, each drawn with its `weight` for every sample):
- `yolo:PATH` / `supervisely:PATH`: real labelled frames (`real_frames.py`);
- a renderer output folder, decoded once into `cache` (`cache.py`) when one is given;
- `toy:COUNT[:SEED]`: procedural frames (tests and smoke runs).
Validation (`val`) takes the same specs; the best checkpoint is chosen on it.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field, fields
from pathlib import Path
from typing import Any

import yaml

from conesight_train.augment import AugmentParams
from conesight_train.detector.augment import DetectorAugmentParams
from conesight_train.detector.data import FrameSource, RendererFrames, ToyFrames
from conesight_train.detector.degrade import DegradeParams
from conesight_train.detector.frame_input import FrameInputParams
from conesight_train.detector.loss import LossParams
from conesight_train.detector.model import DetectorParams
from conesight_train.detector.postprocess import Thresholds


@dataclass(frozen=True)
class SourceSpec:
    """One training source and its share of the samples."""

    path: str
    weight: float = 1.0
    cache: str = ""  # renderer folders only: the decoded cache folder


@dataclass
class TrainConfig:
    """Every setting of a run (defaults: the shipped configuration)."""

    sources: list[SourceSpec] = field(
        default_factory=lambda: [
            SourceSpec("yolo:../shared/data/real-train/fsoco-boxes/train", 0.7),
            SourceSpec("out/sim-train", 0.3, "build/cache/sim-train"),
        ]
    )
    val: str = "yolo:../shared/data/real-train/fsoco-boxes/valid"
    out: str = "build/train/detector"
    steps: int = 2000
    # Stop early once the run has used this much wall-clock time (0: no limit); the learning
    # rate schedule follows the step count, or the budget when that runs out first.
    max_minutes: float = 0.0
    # The same in CPU minutes of the run (its process and data workers; 0: no limit): a budget
    # that a busy machine does not shrink, and the one the detector benchmark compares.
    max_cpu_minutes: float = 0.0
    # One sitting of a longer run: stop after this many steps or wall-clock minutes of this
    # process (0: no limit), saving `last.pt` for `--resume`. Unlike the budgets above it does
    # not touch the learning-rate schedule, so a run spread over sittings is the run it would
    # have been in one. SIGTERM and SIGINT end a sitting the same way, at the end of a step.
    sitting_steps: int = 0
    sitting_minutes: float = 0.0
    # Exponential moving average of the weights (0: off): validation, checkpoints' model_state
    # and export use the averaged weights. Decay ramps up as decay (1 - exp(-updates / ramp)).
    ema_decay: float = 0.0
    ema_ramp_steps: int = 500
    # Forward pass under CPU autocast to bfloat16 (weights, optimiser and loss stay float32):
    # 1.9x the training steps per CPU second on a CPU with AVX512-BF16 (measured, batch 8 of
    # 640x384, one thread); slower where the CPU lacks it.
    bf16: bool = False
    batch_size: int = 8
    lr: float = 2e-3
    weight_decay: float = 1e-4
    warmup_steps: int = 100
    seed: int = 0
    threads: int = 1
    # Where the network trains: "cpu", or "cuda" (a GPU; bfloat16 autocast there too). Data
    # loading stays on the CPU. The checkpoints' history records wall and CPU seconds either
    # way, and `device_name` the device (the compute a card states).
    device: str = "cpu"
    workers: int = 1
    val_every: int = 250
    val_limit: int = 100
    # A checkpoint of the same network to start from ("" = from scratch).
    init_from: str = ""
    input: FrameInputParams = field(default_factory=FrameInputParams)
    augment: DetectorAugmentParams = field(default_factory=DetectorAugmentParams)
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
        if "sources" in d:
            d["sources"] = [
                SourceSpec(s) if isinstance(s, str) else SourceSpec(**s) for s in d["sources"]
            ]
        if "input" in d:
            d["input"] = FrameInputParams(**d["input"])
        if "augment" in d:
            a = dict(d["augment"])
            for key in ("scale_range", "centre_class_weights", "hsv_gains"):
                if key in a:
                    a[key] = tuple(a[key])
            if "photometric" in a:
                a["photometric"] = AugmentParams(**a["photometric"])
            if "degrade" in a:
                g = dict(a["degrade"])
                for key in ("ego_height", "motion_blur_px", "exposure_gain", "jpeg_quality"):
                    if key in g:
                        g[key] = tuple(g[key])
                a["degrade"] = DegradeParams(**g)
            d["augment"] = DetectorAugmentParams(**a)
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


def open_source(spec: str, limit: int | None = None, cache: str = "") -> FrameSource:
    """A source spec (module docs) as frames; `cache` applies to renderer folders."""
    from conesight_train.detector.real_frames import open_real

    if spec.startswith("toy:"):
        parts = spec.split(":")
        count = int(parts[1])
        seed = int(parts[2]) if len(parts) > 2 else 0
        return ToyFrames(count if limit is None else min(count, limit), seed)
    if spec.startswith(("yolo:", "supervisely:")):
        return open_real(spec, limit)
    if cache:
        from conesight_train.detector.cache import CachedFrames, ensure_cache

        return CachedFrames(ensure_cache(spec, cache, 2))
    return RendererFrames(spec, limit)
