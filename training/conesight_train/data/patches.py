"""Keypoint patches: the sample type, the source interface, in-memory and real-crop sources,
and the torch Dataset that applies augmentation.

A source is anything with `__len__` and `__getitem__(i) -> KeypointPatch`; the renderer's patch
reader, the real crops and the in-memory arrays used by tests all are.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np
import torch

from conesight_train.crop import CropParams, PixelBox, crop_patch
from conesight_train.data.supervisely_keypoints import KeypointCrop
from conesight_train.keypoints import KEYPOINT_COUNT
from conesight_train.preprocess import patch_to_input
from conesight_train.seed import worker_seed


@dataclass(frozen=True)
class KeypointPatch:
    """An RGB patch (N x N x 3 uint8) and its 7 keypoints (x, y) in patch pixels."""

    patch_rgb: np.ndarray
    keypoints_px: np.ndarray  # (7, 2) float32


class PatchSource(Protocol):
    """Random access to keypoint patches."""

    def __len__(self) -> int: ...

    def __getitem__(self, index: int) -> KeypointPatch: ...


class InMemoryPatches:
    """Patches held in arrays: `patches_rgb` (M, N, N, 3) uint8, `keypoints_px` (M, 7, 2)."""

    def __init__(self, patches_rgb: np.ndarray, keypoints_px: np.ndarray) -> None:
        if patches_rgb.ndim != 4 or patches_rgb.shape[3] != 3 or patches_rgb.dtype != np.uint8:
            raise ValueError(f"patches must be (M, N, N, 3) uint8, got {patches_rgb.shape}")
        if keypoints_px.shape != (patches_rgb.shape[0], KEYPOINT_COUNT, 2):
            raise ValueError(
                f"keypoints must be ({patches_rgb.shape[0]}, 7, 2), got {keypoints_px.shape}"
            )
        self.patches_rgb = patches_rgb
        self.keypoints_px = keypoints_px.astype(np.float32)

    def __len__(self) -> int:
        return self.patches_rgb.shape[0]

    def __getitem__(self, index: int) -> KeypointPatch:
        return KeypointPatch(self.patches_rgb[index], self.keypoints_px[index])


class Subset:
    """The samples of `source` at `indices`."""

    def __init__(self, source: PatchSource, indices: Sequence[int]) -> None:
        self.source = source
        self.indices = list(indices)

    def __len__(self) -> int:
        return len(self.indices)

    def __getitem__(self, index: int) -> KeypointPatch:
        return self.source[self.indices[index]]


def read_rgb(path: Path) -> np.ndarray:
    """An image file as HxWx3 uint8 RGB; raises FileNotFoundError/ValueError naming the file."""
    image = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if image is None:
        if not path.is_file():
            raise FileNotFoundError(f"{path}: no such image")
        raise ValueError(f"{path}: not a readable image")
    return cv2.cvtColor(image, cv2.COLOR_BGR2RGB)


class RealCropPatches:
    """Keypoint crops (real photographs) as 80x80 patches for evaluation.

    Each crop is taken as the detector box and cut by the crop rule; keypoints map by the same
    rule, so errors come out in 80x80 patch pixels. The rule's square is larger than a crop
    (side 1.2 x the longer side), and a detector box in a full frame would have image around
    it: `outside="replicate"` (default) extends the crop by repeating its border pixels
    before cutting (geometry unchanged), `outside="fill"` uses the rule's fill colour (black
    bands the networks never see in rendered patches).

    `reframe = (dx, dy, scale)` moves the box by (dx, dy) times its (width, height) and scales
    it by `scale` about its centre before cutting: the crop as another labeller or detector
    would have framed it (keypoints follow, so errors stay comparable).
    """

    OUTSIDE_MODES = ("replicate", "fill")

    def __init__(
        self,
        crops: Sequence[KeypointCrop],
        params: CropParams | None = None,
        outside: str = "replicate",
        reframe: tuple[float, float, float] = (0.0, 0.0, 1.0),
    ) -> None:
        if reframe[2] <= 0:
            raise ValueError(f"reframe scale must be > 0, got {reframe[2]}")
        self.reframe = reframe
        if outside not in self.OUTSIDE_MODES:
            raise ValueError(f"outside={outside!r}; expected one of {self.OUTSIDE_MODES}")
        self.crops = list(crops)
        self.params = params or CropParams()
        self.outside = outside
        self._images: dict[int, np.ndarray] = {}  # decoded crops (small; a few MB in all)

    def __len__(self) -> int:
        return len(self.crops)

    def framed(self, index: int) -> tuple[np.ndarray, PixelBox, np.ndarray]:
        """Crop `index` as (image with its outside filled, box as framed, keypoints in image px)."""
        crop = self.crops[index]
        image = self._images.get(index)
        if image is None:
            image = read_rgb(crop.image_path)
            self._images[index] = image
        height, width = image.shape[:2]
        if (width, height) != (crop.width_px, crop.height_px):
            raise ValueError(
                f"{crop.image_path}: image is {width}x{height}, its label says "
                f"{crop.width_px}x{crop.height_px}"
            )
        pad = 0
        dx, dy, scale = self.reframe
        if self.outside == "replicate":
            side = max(width, height) * (1.0 + 2.0 * self.params.margin_fraction)
            shift = max(abs(dx) * width, abs(dy) * height)
            pad = int(np.ceil(side * max(1.0, scale) / 2 + shift)) + 2
            image = cv2.copyMakeBorder(image, pad, pad, pad, pad, cv2.BORDER_REPLICATE)
        bbox = PixelBox.from_pixel_range(pad, pad, pad + width - 1, pad + height - 1)
        if self.reframe != (0.0, 0.0, 1.0):
            cx = 0.5 * (bbox.x_min_px + bbox.x_max_px) + dx * bbox.width_px
            cy = 0.5 * (bbox.y_min_px + bbox.y_max_px) + dy * bbox.height_px
            half_w, half_h = 0.5 * scale * bbox.width_px, 0.5 * scale * bbox.height_px
            bbox = PixelBox(cx - half_w, cy - half_h, cx + half_w, cy + half_h)
        return image, bbox, crop.keypoints_px + pad

    def __getitem__(self, index: int) -> KeypointPatch:
        image, bbox, keypoints_px = self.framed(index)
        patch, transform = crop_patch(image, bbox, self.params)
        keypoints = transform.patch_from_image(keypoints_px).astype(np.float32)
        return KeypointPatch(patch, keypoints)


Augmenter = Callable[[KeypointPatch, np.random.Generator], KeypointPatch]


class KeypointDataset(torch.utils.data.Dataset):
    """Torch view of a source: (float32 [3, N, N] raw 0..255, float32 [7, 2] keypoints px).

    With an augmenter, sample `i` in epoch `e` is augmented with the seed (seed, e, i), so runs
    are reproducible and a resumed run sees the same data as an uninterrupted one.
    """

    def __init__(
        self, source: PatchSource, augment: Augmenter | None = None, seed: int = 0
    ) -> None:
        self.source = source
        self.augment = augment
        self.seed = seed
        self.epoch = 0

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __len__(self) -> int:
        return len(self.source)

    def __getitem__(self, index: int) -> tuple[torch.Tensor, torch.Tensor]:
        sample = self.source[index]
        if self.augment is not None:
            rng = np.random.default_rng(worker_seed(self.seed, self.epoch, index))
            sample = self.augment(sample, rng)
        image = torch.from_numpy(patch_to_input(sample.patch_rgb))
        return image, torch.from_numpy(np.asarray(sample.keypoints_px, dtype=np.float32))
