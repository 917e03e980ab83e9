"""The torch datasets: `MixedDataset` draws training crops from several frame sources by weight
(real and rendered frames in one batch), seeded per (epoch, index) so augmentation is
reproducible and resumable; `FrameDataset` gives whole frames, unaugmented."""

from __future__ import annotations

import numpy as np
import torch

from conesight_train.detector.augment import DetectorAugmentParams, to_input, train_sample
from conesight_train.detector.data import FrameSource
from conesight_train.detector.frame_input import FrameInputParams
from conesight_train.detector.model import CLASS_NAMES
from conesight_train.detector.targets import encode
from conesight_train.seed import worker_seed

Sample = tuple[torch.Tensor, dict[str, torch.Tensor]]


def _pack(image: np.ndarray, targets: object) -> Sample:
    return torch.from_numpy(image), {k: torch.from_numpy(v) for k, v in vars(targets).items()}


class MixedDataset(torch.utils.data.Dataset):
    """`length` samples per epoch; each picks a source by weight, then a frame, uniformly."""

    def __init__(
        self,
        sources: list[tuple[FrameSource, float]],
        length: int,
        input_params: FrameInputParams,
        augment: DetectorAugmentParams,
        seed: int = 0,
    ) -> None:
        if not sources or any(len(s) == 0 for s, _ in sources):
            raise ValueError("every training source needs at least one frame")
        weights = np.array([w for _, w in sources], np.float64)
        if np.any(weights < 0) or weights.sum() <= 0:
            raise ValueError(f"source weights {weights.tolist()} must be >= 0 with a positive sum")
        self.sources = [s for s, _ in sources]
        self.cumulative = np.cumsum(weights / weights.sum())
        self.length = length
        self.input_params = input_params
        self.augment = augment
        self.seed = seed
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        """Selects the draws of this epoch."""
        self.epoch = epoch

    def __len__(self) -> int:
        return self.length

    def pick(self, index: int) -> tuple[int, int, np.random.Generator]:
        """(source, frame, generator for the augmentation) of sample `index` this epoch."""
        rng = np.random.default_rng(worker_seed(self.seed, self.epoch, index))
        source = min(
            int(np.searchsorted(self.cumulative, rng.random(), side="right")), len(self.sources) - 1
        )
        return source, int(rng.integers(len(self.sources[source]))), rng

    def __getitem__(self, index: int) -> Sample:
        source, frame_index, rng = self.pick(index)
        sample = train_sample(
            self.sources[source][frame_index], self.input_params, rng, self.augment
        )
        targets = encode(
            sample.boxes_px,
            sample.classes,
            len(CLASS_NAMES),
            (self.augment.crop_height_px, self.augment.crop_width_px),
            sample.difficult,
        )
        return _pack(sample.image, targets)


class FrameDataset(torch.utils.data.Dataset):
    """Whole frames at the inference input, with targets (tests, validation losses)."""

    def __init__(self, source: FrameSource, input_params: FrameInputParams) -> None:
        self.source = source
        self.input_params = input_params

    def __len__(self) -> int:
        return len(self.source)

    def __getitem__(self, index: int) -> Sample:
        sample = to_input(self.source[index], self.input_params)
        p = self.input_params
        targets = encode(
            sample.boxes_px,
            sample.classes,
            len(CLASS_NAMES),
            (p.input_height_px, p.input_width_px),
            sample.difficult,
        )
        return _pack(sample.image, targets)
