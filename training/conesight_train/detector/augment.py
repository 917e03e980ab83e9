"""Frame -> network input: the whole frame for inference (`to_input`, the rule of
`frame_input.py`), and seeded random crops for training (`train_sample`).

A training sample is a `crop_width x crop_height` window of the frame rescaled to a random
multiple (`scale_range`, log-uniform) of its inference scale, so the network sees cones at
every size the same camera gives them and at those of other resolutions. The window is centred
near a random cone (`p_on_cone`) or anywhere, and may reach past the frame (grey fill, as the
inference input's padding): cones appear in every part of the input, the property that makes
the detector indifferent to camera pitch, mount height and the horizon. The cone a window is
centred on is drawn with a weight per class (`centre_class_weights`), so the rare orange and
large orange cones are seen more often than their share of the labels. Then a horizontal flip
(classes unchanged: a mirrored blue cone is still blue), an HSV jitter that keeps hue within a
few degrees (`hsv_gains`, YOLO's recipe: the keypoint pipeline's per-channel gains and offsets
turn a yellow cone orange, and yellow and orange are two classes here), and the rest of the
photometric augmentation of the keypoint pipeline (gamma, blur, noise, JPEG).

Frames come at full resolution (`LabelledFrame`) or box-filtered by a factor (`ReducedFrame`,
the renderer cache); boxes are always in continuous full-frame pixels. Boxes keep their part
inside the window; one keeping less than MIN_VISIBLE_FRACTION of its area is dropped, and its
cells left out of the negatives by `targets.encode` only when it is marked difficult.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from conesight_train.augment import AugmentParams, photometric
from conesight_train.detector.cache import ReducedFrame
from conesight_train.detector.data import LabelledFrame
from conesight_train.detector.degrade import DegradeParams, degrade
from conesight_train.detector.frame_input import FILL, FrameInputParams, frame_to_input
from conesight_train.detector.negatives import hard_negatives
from conesight_train.detector.paste import LARGE_ORANGE, load_bank, paste_cones

MIN_VISIBLE_FRACTION = 0.4


@dataclass(frozen=True)
class DetectorAugmentParams:
    """Crop size, probabilities and ranges (defaults: the training configuration)."""

    crop_width_px: int = 640
    crop_height_px: int = 384
    # Multiples of the frame's inference scale (log-uniform).
    scale_range: tuple[float, float] = (0.6, 1.6)
    p_on_cone: float = 0.7
    # Weight of a cone of each class (blue, yellow, orange, large orange) when choosing the
    # cone a window is centred on: about the square root of the classes' inverse frequency in
    # the real training frames (8,310 / 8,509 / 1,870 / 462 labels).
    centre_class_weights: tuple[float, ...] = (1.0, 1.0, 2.0, 4.0)
    # Onboard video (issue 38): the whole frame degraded before its crop (`degrade.py`:
    # 640 rows, the car's body, motion blur, exposure, glare, overlay, JPEG q30-50); real
    # frames only.
    p_degrade: float = 0.0
    degrade: DegradeParams = field(default_factory=DegradeParams)
    # Hard negatives (issue 38): a window centred on a mined false positive of an earlier
    # model (`negatives.py`, JSON of boxes per frame name) with this probability, when the
    # frame has one.
    hard_negatives: str = ""
    p_on_negative: float = 0.0
    # Copy-paste (issue 38): with this probability a window gets 1-2 real large orange cones
    # from the bank `paste_bank` (`paste.py`), where they overlap no labelled cone.
    paste_bank: str = ""
    p_paste: float = 0.0
    p_flip: float = 0.5
    # HSV jitter: hue shift as a fraction of the circle (0.015 = +-5.4 degrees), saturation
    # and value gains 1 +- these (uniform); applied with probability p_hsv.
    p_hsv: float = 0.8
    hsv_gains: tuple[float, float, float] = (0.015, 0.6, 0.35)
    # The per-channel colour gain and offset stay off (p_colour 0): they shift hue by tens of
    # degrees; gamma, blur, noise and JPEG as in the keypoint pipeline. Exposure, glare and low
    # resolution (added for the keypoints, issue 37) stay off: the shipped detector was
    # trained without them.
    photometric: AugmentParams = field(
        default_factory=lambda: AugmentParams(
            p_colour=0.0,
            p_blur=0.3,
            blur_sigma_max_px=1.0,
            p_jpeg=0.3,
            p_exposure=0.0,
            p_glare=0.0,
            p_low_resolution=0.0,
        )
    )


@dataclass(frozen=True)
class InputSample:
    """A network input float32 [3, H, W] (raw 0..255) with its boxes in continuous input px."""

    image: np.ndarray
    boxes_px: np.ndarray
    classes: np.ndarray
    range_m: np.ndarray
    difficult: np.ndarray
    scale_xy: tuple[float, float]  # input px per frame px (inference; 0 for training crops)


def hsv_jitter(
    image: np.ndarray, rng: np.random.Generator, gains: tuple[float, float, float]
) -> np.ndarray:
    """RGB uint8 image with its hue shifted by up to gains[0] of the circle and its saturation
    and value scaled by 1 +- gains[1], gains[2] (lookup tables on OpenCV's 8-bit HSV)."""
    dh, ds, dv = rng.uniform(-1.0, 1.0, 3) * np.asarray(gains)
    hue, sat, val = cv2.split(cv2.cvtColor(image, cv2.COLOR_RGB2HSV))
    x = np.arange(256, dtype=np.float32)
    lut_hue = np.mod(np.round(x + dh * 180.0), 180).astype(np.uint8)
    lut_sat = np.clip(np.round(x * (1.0 + ds)), 0, 255).astype(np.uint8)
    lut_val = np.clip(np.round(x * (1.0 + dv)), 0, 255).astype(np.uint8)
    hsv = cv2.merge((cv2.LUT(hue, lut_hue), cv2.LUT(sat, lut_sat), cv2.LUT(val, lut_val)))
    return cv2.cvtColor(hsv, cv2.COLOR_HSV2RGB)


def _keep_visible(
    boxes: np.ndarray, frame: LabelledFrame | ReducedFrame, w: float, h: float
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    return _keep_visible_labels(boxes, frame.classes, frame.range_m, frame.difficult_mask(), w, h)


def _keep_visible_labels(
    boxes: np.ndarray,
    classes: np.ndarray,
    ranges: np.ndarray,
    difficult: np.ndarray,
    w: float,
    h: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    if len(boxes) == 0:
        return boxes.reshape(0, 4), classes, ranges, difficult
    clipped = np.clip(boxes, 0, [w, h, w, h])
    area = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    kept = (clipped[:, 2] - clipped[:, 0]) * (clipped[:, 3] - clipped[:, 1])
    keep = kept >= MIN_VISIBLE_FRACTION * np.maximum(area, 1e-9)
    return clipped[keep], classes[keep], ranges[keep], difficult[keep]


def to_input(frame: LabelledFrame, params: FrameInputParams) -> InputSample:
    """The whole frame as network input (inference), boxes mapped into it."""
    image, (sx, sy) = frame_to_input(frame.image_rgb, params)
    boxes = frame.boxes_px.astype(np.float64).reshape(-1, 4) * [sx, sy, sx, sy]
    return InputSample(
        image,
        *_keep_visible(boxes, frame, params.input_width_px, params.input_height_px),
        (sx, sy),
    )


def _stored(frame: LabelledFrame | ReducedFrame) -> tuple[np.ndarray, float, tuple[int, int]]:
    """(stored image, stored px per frame px, frame (h, w))."""
    if isinstance(frame, ReducedFrame):
        return frame.image_rgb, 1.0 / frame.factor, frame.frame_hw
    h, w = frame.image_rgb.shape[:2]
    return frame.image_rgb, 1.0, (h, w)


def train_sample(
    frame: LabelledFrame | ReducedFrame,
    params: FrameInputParams,
    rng: np.random.Generator,
    p: DetectorAugmentParams | None = None,
) -> InputSample:
    """A random training crop of `frame` (module docs)."""
    p = p or DetectorAugmentParams()
    negatives = np.zeros((0, 4))
    if p.hard_negatives and isinstance(frame, LabelledFrame):
        negatives = hard_negatives(p.hard_negatives).get(frame.name, negatives)
    if p.p_degrade > 0 and isinstance(frame, LabelledFrame) and rng.random() < p.p_degrade:
        w_before = frame.image_rgb.shape[1]
        frame = degrade(frame, rng, p.degrade)
        negatives = negatives * (frame.image_rgb.shape[1] / w_before)
    stored, per_frame_px, frame_hw = _stored(frame)
    sx0, sy0 = params.scale_xy(frame_hw)
    lo, hi = np.log(p.scale_range[0]), np.log(p.scale_range[1])
    scale = float(np.exp(rng.uniform(lo, hi))) * min(sx0, sy0)
    # Resize the stored image to `scale` input px per frame px.
    r = scale / per_frame_px
    sh, sw = stored.shape[:2]
    new_w, new_h = max(1, round(sw * r)), max(1, round(sh * r))
    interpolation = cv2.INTER_AREA if r < 1 else cv2.INTER_LINEAR
    scaled = cv2.resize(stored, (new_w, new_h), interpolation=interpolation)
    kx, ky = new_w / sw * per_frame_px, new_h / sh * per_frame_px  # input px per frame px
    boxes = frame.boxes_px.astype(np.float64).reshape(-1, 4) * [kx, ky, kx, ky]
    cw, ch = p.crop_width_px, p.crop_height_px
    usable = np.nonzero(~frame.difficult_mask() & (frame.classes >= 0))[0]
    if len(negatives) and rng.random() < p.p_on_negative:
        b = negatives[rng.integers(len(negatives))] * [kx, ky, kx, ky]
        x0 = (b[0] + b[2]) / 2 - rng.uniform(0.1, 0.9) * cw
        y0 = (b[1] + b[3]) / 2 - rng.uniform(0.1, 0.9) * ch
    elif len(usable) and rng.random() < p.p_on_cone:
        weights = np.asarray(p.centre_class_weights, np.float64)[frame.classes[usable]]
        b = boxes[usable[rng.choice(len(usable), p=weights / weights.sum())]]
        x0 = (b[0] + b[2]) / 2 - rng.uniform(0.1, 0.9) * cw
        y0 = (b[1] + b[3]) / 2 - rng.uniform(0.1, 0.9) * ch
    else:
        x0 = rng.uniform(-0.25 * cw, max(-0.25 * cw, new_w - 0.75 * cw))
        y0 = rng.uniform(-0.25 * ch, max(-0.25 * ch, new_h - 0.75 * ch))
    ox, oy = round(x0), round(y0)
    canvas = np.full((ch, cw, 3), FILL, np.uint8)
    src_x0, src_y0 = max(ox, 0), max(oy, 0)
    src_x1, src_y1 = min(ox + cw, new_w), min(oy + ch, new_h)
    if src_x1 > src_x0 and src_y1 > src_y0:
        canvas[src_y0 - oy : src_y1 - oy, src_x0 - ox : src_x1 - ox] = scaled[
            src_y0:src_y1, src_x0:src_x1
        ]
    boxes -= [ox, oy, ox, oy]
    classes, ranges, difficult = frame.classes, frame.range_m, frame.difficult_mask()
    if p.paste_bank and rng.random() < p.p_paste:
        canvas, pasted = paste_cones(
            canvas, boxes, load_bank(p.paste_bank), rng, int(rng.integers(1, 3))
        )
        boxes = np.concatenate([boxes, pasted])
        classes = np.concatenate([classes, np.full(len(pasted), LARGE_ORANGE)])
        ranges = np.concatenate([ranges, np.full(len(pasted), np.nan)])
        difficult = np.concatenate([difficult, np.zeros(len(pasted), bool)])
    if rng.random() < p.p_flip:
        canvas = canvas[:, ::-1]
        boxes[:, [0, 2]] = cw - boxes[:, [2, 0]]
    canvas = np.ascontiguousarray(canvas)
    if rng.random() < p.p_hsv:
        canvas = hsv_jitter(canvas, rng, p.hsv_gains)
    image = photometric(canvas, rng, p.photometric)
    image = np.ascontiguousarray(image.transpose(2, 0, 1), dtype=np.float32)
    return InputSample(
        image, *_keep_visible_labels(boxes, classes, ranges, difficult, cw, ch), (0.0, 0.0)
    )
