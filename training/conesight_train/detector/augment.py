"""Frame -> (network input, boxes in input pixels), with seeded augmentation.

Geometric, on the full-resolution band before the box filter (so training sees exactly the
inference preprocessing): band jitter (the band's top row moves by up to `band_jitter_px`,
standing in for pitch and horizon changes), scale about the band's centre column and top row
(cones nearer or farther), horizontal flip (boxes mirror; classes are unchanged: a mirrored
blue cone is still blue). Photometric (colour, gamma, blur, noise, JPEG): the keypoint
pipeline's `augment.photometric`, applied after the box filter (at the network's resolution,
a quarter of the pixels).

Boxes keep their part inside the input; a box keeping less than MIN_VISIBLE_FRACTION of its
area is dropped (and its region left out of the negatives by `targets.encode` through
MIN_BOX_PX only when tiny; partial cones at the border remain positives).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from conesight_train.augment import AugmentParams, photometric
from conesight_train.detector.band import BandParams, band_to_input
from conesight_train.detector.cache import ReducedFrame
from conesight_train.detector.data import LabelledFrame

MIN_VISIBLE_FRACTION = 0.4


@dataclass(frozen=True)
class DetectorAugmentParams:
    """Probabilities and ranges (defaults: the training configuration)."""

    band_jitter_px: int = 48
    scale_range: tuple[float, float] = (0.8, 1.25)
    p_scale: float = 0.6
    p_flip: float = 0.5
    photometric: AugmentParams = field(
        default_factory=lambda: AugmentParams(p_blur=0.3, blur_sigma_max_px=1.0, p_jpeg=0.3)
    )


@dataclass(frozen=True)
class InputSample:
    """A network input float32 [3, H, W] (raw 0..255) with its boxes in continuous input px."""

    image: np.ndarray
    boxes_px: np.ndarray
    classes: np.ndarray
    range_m: np.ndarray
    difficult: np.ndarray
    top_px: int  # the frame row of the input's top edge (before augmentation)


def _clip_boxes(
    boxes: np.ndarray, frame: LabelledFrame, w: float, h: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    classes, ranges, difficult = frame.classes, frame.range_m, frame.difficult_mask()
    if len(boxes) == 0:
        return boxes.reshape(0, 4), classes, ranges, difficult
    clipped = np.clip(boxes, 0, [w, h, w, h])
    area = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    kept = (clipped[:, 2] - clipped[:, 0]) * (clipped[:, 3] - clipped[:, 1])
    keep = kept >= MIN_VISIBLE_FRACTION * np.maximum(area, 1e-9)
    return clipped[keep], classes[keep], ranges[keep], difficult[keep]


def to_input(
    frame: LabelledFrame | ReducedFrame,
    band: BandParams,
    rng: np.random.Generator | None = None,
    params: DetectorAugmentParams | None = None,
) -> InputSample:
    """The band of `frame` as network input; augmented when `rng` is given. A `ReducedFrame`
    (the training cache) is only taken with `rng` (training); see `_reduced_to_input`."""
    if isinstance(frame, ReducedFrame):
        height, width = frame.frame_hw
        if rng is None:
            raise ValueError(
                "a cached (reduced) frame is for augmented training only: evaluate on the "
                "renderer folder, whose full-resolution frames give the exact preprocessing"
            )
    else:
        height, width = frame.image_rgb.shape[:2]
    top = band.top_for(height, frame.band_top_px)
    boxes = frame.boxes_px.astype(np.float64).reshape(-1, 4).copy()
    if rng is None:
        image = band_to_input(frame.image_rgb, band, top)
        boxes[:, [1, 3]] -= top
        boxes /= band.factor
        return InputSample(
            image,
            *_clip_boxes(boxes, frame, band.input_width_px, band.input_height_px),
            top,
        )
    p = params or DetectorAugmentParams()
    if isinstance(frame, ReducedFrame):
        return _reduced_to_input(frame, band, top, rng, p)
    top = int(
        np.clip(
            top + rng.integers(-p.band_jitter_px, p.band_jitter_px + 1),
            0,
            height - band.band_height_px,
        )
    )
    scale = float(rng.uniform(*p.scale_range)) if rng.random() < p.p_scale else 1.0
    flip = rng.random() < p.p_flip
    # Continuous coordinates: x' = a x + bx, y' = scale (y - top) (anchored at the band top).
    a = -scale if flip else scale
    bx = width / 2 - a * width / 2
    by = -scale * top
    # cv2 works on pixel centres: p' = a p + (a * 0.5 + b - 0.5).
    matrix = np.array([[a, 0.0, a * 0.5 + bx - 0.5], [0.0, scale, scale * 0.5 + by - 0.5]])
    warped = cv2.warpAffine(
        frame.image_rgb,
        matrix,
        (width, band.band_height_px),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REFLECT_101,
    )
    # Photometric after the box filter: 1/factor^2 of the pixels (blur, noise and JPEG act at
    # the network's resolution).
    reduced = np.clip(band_to_input(warped, band, 0) + 0.5, 0, 255).astype(np.uint8)
    image = photometric(reduced.transpose(1, 2, 0), rng, p.photometric)
    image = np.ascontiguousarray(image.transpose(2, 0, 1), dtype=np.float32)
    xs = boxes[:, [0, 2]] * a + bx
    boxes[:, 0], boxes[:, 2] = xs.min(axis=1), xs.max(axis=1)
    boxes[:, [1, 3]] = boxes[:, [1, 3]] * scale + by
    boxes /= band.factor
    return InputSample(
        image,
        *_clip_boxes(boxes, frame, band.input_width_px, band.input_height_px),
        top,
    )


def _reduced_to_input(
    frame: ReducedFrame,
    band: BandParams,
    top: int,
    rng: np.random.Generator,
    p: DetectorAugmentParams,
) -> InputSample:
    """`to_input`'s augmented path on a frame already box-filtered by the band's factor: the
    same draws and the same continuous mapping, applied at the reduced resolution (the band's
    top row is kept on a multiple of the factor so an unscaled sample is exactly the
    inference input's pixels, rounded to uint8 as on the full-resolution path)."""
    f = band.factor
    if frame.factor != f:
        raise ValueError(f"cache factor {frame.factor} does not match the band's factor {f}")
    height, width = frame.frame_hw
    top = int(
        np.clip(
            top + rng.integers(-p.band_jitter_px, p.band_jitter_px + 1),
            0,
            height - band.band_height_px,
        )
    )
    top -= top % f
    scale = float(rng.uniform(*p.scale_range)) if rng.random() < p.p_scale else 1.0
    flip = rng.random() < p.p_flip
    a = -scale if flip else scale
    bx = width / 2 - a * width / 2
    # Reduced continuous coordinates u = x / f: u' = a u + bx / f, v' = scale (v - top / f).
    matrix = np.array(
        [
            [a, 0.0, a * 0.5 + bx / f - 0.5],
            [0.0, scale, scale * 0.5 - scale * top / f - 0.5],
        ]
    )
    reduced = cv2.warpAffine(
        frame.image_rgb,
        matrix,
        (band.input_width_px, band.input_height_px),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_REFLECT_101,
    )
    image = photometric(reduced, rng, p.photometric)
    image = np.ascontiguousarray(image.transpose(2, 0, 1), dtype=np.float32)
    boxes = frame.boxes_px.astype(np.float64).reshape(-1, 4).copy()
    xs = boxes[:, [0, 2]] * a + bx
    boxes[:, 0], boxes[:, 2] = xs.min(axis=1), xs.max(axis=1)
    boxes[:, [1, 3]] = (boxes[:, [1, 3]] - top) * scale
    boxes /= f
    return InputSample(
        image,
        *_clip_boxes(boxes, frame, band.input_width_px, band.input_height_px),
        top,
    )
