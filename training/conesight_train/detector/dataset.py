"""The torch dataset: labelled frames -> (input float32 [3, H, W], targets), seeded per
(epoch, index) so augmentation is reproducible and resumable."""

from __future__ import annotations

import numpy as np
import torch

from conesight_train.detector.augment import DetectorAugmentParams, to_input
from conesight_train.detector.band import BandParams
from conesight_train.detector.data import FrameSource
from conesight_train.detector.model import CLASS_NAMES
from conesight_train.detector.targets import encode
from conesight_train.seed import worker_seed


class DetectorDataset(torch.utils.data.Dataset):
    """See the module docs; `augment` False gives the plain inference preprocessing."""

    def __init__(
        self,
        source: FrameSource,
        band: BandParams,
        augment: bool = False,
        seed: int = 0,
        params: DetectorAugmentParams | None = None,
    ) -> None:
        self.source = source
        self.band = band
        self.augment = augment
        self.seed = seed
        self.epoch = 0
        self.params = params or DetectorAugmentParams()

    def set_epoch(self, epoch: int) -> None:
        """Selects the augmentation draws of this epoch."""
        self.epoch = epoch

    def __len__(self) -> int:
        return len(self.source)

    def __getitem__(self, index: int) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        rng = (
            np.random.default_rng(worker_seed(self.seed, self.epoch, index))
            if self.augment
            else None
        )
        sample = to_input(self.source[index], self.band, rng, self.params)
        targets = encode(
            sample.boxes_px,
            sample.classes,
            len(CLASS_NAMES),
            (self.band.input_height_px, self.band.input_width_px),
            sample.difficult,
        )
        return torch.from_numpy(sample.image), {
            k: torch.from_numpy(v) for k, v in vars(targets).items()
        }
