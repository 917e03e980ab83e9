"""Detection data: frames with boxes, from the renderer's YOLO output or procedural toy frames,
and the torch dataset that augments and encodes them.

A `DetectionSample` is already at the detector's input size (`detection/frames.py` rule), with
boxes [M, 4] in input pixels (continuous edges) and classes [M] (indices of CONE_CLASSES).
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np
import torch

from conesight_train.augment import AugmentParams, photometric
from conesight_train.data.errors import LabelError
from conesight_train.data.patches import read_rgb
from conesight_train.data.toy_cones import toy_cone_patches
from conesight_train.data.yolo_txt import CONE_CLASSES, read_yolo_txt
from conesight_train.detection.frames import INPUT_HEIGHT_PX, INPUT_WIDTH_PX, frame_to_input
from conesight_train.detection.targets import encode
from conesight_train.preprocess import patch_to_input
from conesight_train.seed import worker_seed

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")


@dataclass(frozen=True)
class DetectionSample:
    """An input-sized RGB image, its boxes [M, 4] (input px) and classes [M]."""

    image_rgb: np.ndarray
    boxes_px: np.ndarray
    classes: np.ndarray


class DetectionSource(Protocol):
    def __len__(self) -> int: ...

    def __getitem__(self, index: int) -> DetectionSample: ...


class YoloFrames:
    """`ROOT/images/NAME.{png,jpg}` with `ROOT/labels/NAME.txt` (the renderer's yolo format)."""

    def __init__(
        self, root: str | Path, input_wh: tuple[int, int] = (INPUT_WIDTH_PX, INPUT_HEIGHT_PX)
    ) -> None:
        self.root = Path(root)
        self.input_wh = input_wh
        images = sorted(p for p in (self.root / "images").glob("*") if p.suffix in IMAGE_SUFFIXES)
        if not images:
            raise LabelError(self.root / "images", "no images; render with the yolo format")
        self.items = []
        for image in images:
            label = self.root / "labels" / f"{image.stem}.txt"
            if not label.is_file():
                raise LabelError(label, f"missing: every image needs a label file ({image.name})")
            self.items.append((image, label))

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> DetectionSample:
        image_path, label_path = self.items[index]
        frame = read_rgb(image_path)
        height, width = frame.shape[:2]
        boxes = read_yolo_txt(label_path, width, height)
        image, transform = frame_to_input(frame, *self.input_wh)
        edges = np.array(
            [[b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px] for b in boxes], np.float64
        ).reshape(-1, 4)
        classes = np.array([b.class_id for b in boxes], np.int64)
        return DetectionSample(image, transform.input_from_frame(edges), classes)


def toy_frames(
    count: int,
    seed: int,
    cones_per_frame: int = 6,
    width_px: int = INPUT_WIDTH_PX,
    height_px: int = INPUT_HEIGHT_PX,
) -> list[DetectionSample]:
    """Procedural frames at input size: toy cone patches pasted at random sizes (tests)."""
    rng = np.random.default_rng(seed)
    patches = toy_cone_patches(count * cones_per_frame, seed + 1)
    frames = []
    for f in range(count):
        image = np.full((height_px, width_px, 3), rng.integers(60, 200, 3), np.uint8)
        boxes, classes = [], []
        for c in range(cones_per_frame):
            sample = patches[f * cones_per_frame + c]
            size = int(rng.integers(24, min(120, height_px // 2)))
            x0 = int(rng.integers(0, width_px - size))
            y0 = int(rng.integers(0, height_px - size))
            image[y0 : y0 + size, x0 : x0 + size] = cv2.resize(
                sample.patch_rgb, (size, size), interpolation=cv2.INTER_AREA
            )
            s = size / sample.patch_rgb.shape[0]
            k = (sample.keypoints_px + 0.5) * s - 0.5 + np.array([x0, y0])
            boxes.append([k[:, 0].min(), k[:, 1].min(), k[:, 0].max(), k[:, 1].max()])
            classes.append(int(rng.integers(len(CONE_CLASSES))))
        frames.append(DetectionSample(image, np.array(boxes), np.array(classes, np.int64)))
    return frames


def flip_horizontal(sample: DetectionSample) -> DetectionSample:
    """Mirror image and boxes (x -> W - 1 - x on pixel centres; edges swap)."""
    width = sample.image_rgb.shape[1]
    boxes = sample.boxes_px.copy()
    boxes[:, [0, 2]] = (width - 1) - sample.boxes_px[:, [2, 0]]
    return DetectionSample(np.ascontiguousarray(sample.image_rgb[:, ::-1]), boxes, sample.classes)


class DetectionDataset(torch.utils.data.Dataset):
    """(image float32 [3, H, W] raw 0..255, targets dict of tensors) with seeded augmentation."""

    def __init__(self, source: DetectionSource, augment: bool = False, seed: int = 0) -> None:
        self.source = source
        self.augment = augment
        self.seed = seed
        self.epoch = 0
        self.params = AugmentParams()

    def set_epoch(self, epoch: int) -> None:
        self.epoch = epoch

    def __len__(self) -> int:
        return len(self.source)

    def __getitem__(self, index: int) -> tuple[torch.Tensor, dict[str, torch.Tensor]]:
        sample = self.source[index]
        if self.augment:
            rng = np.random.default_rng(worker_seed(self.seed, self.epoch, index))
            if rng.random() < 0.5:
                sample = flip_horizontal(sample)
            sample = DetectionSample(
                photometric(sample.image_rgb, rng, self.params), sample.boxes_px, sample.classes
            )
        targets = encode(
            sample.boxes_px, sample.classes, len(CONE_CLASSES), sample.image_rgb.shape[:2]
        )
        tensors = {k: torch.from_numpy(v) for k, v in vars(targets).items()}
        return torch.from_numpy(patch_to_input(sample.image_rgb)), tensors
