"""Boxes -> CenterNet training targets at STRIDE_PX, with tall Gaussian peaks.

Boxes are continuous input-pixel edges (x_min, y_min, x_max, y_max; the image spans [0, W]).
A box's centre c falls in cell floor(c / STRIDE_PX); the class heatmap is 1 there, with a
Gaussian around it whose sigmas are SIGMA_FRACTION of the box's width and height in cells
(at least MIN_SIGMA_CELLS), so peaks are as tall and narrow as the cones (max over boxes).
Regression targets at the centre cell: dx, dy = centre / STRIDE - cell - 0.5,
log_h = log(height / STRIDE), log_aspect = log(width / height / ASPECT_PRIOR).
Boxes whose centre is outside the input are skipped; difficult boxes and boxes smaller than
MIN_BOX_PX on a side are not positives, and their cells are marked "ignore" (no negative loss).

Dense regression (TTFNet, Liu et al. 2020: more regression samples per object make CenterNet
converge in a fraction of its epochs): every cell where an object's Gaussian is at least
DENSE_MIN_GAUSS also regresses that object's box, relative to its own cell (so dx, dy reach
beyond +-0.5), weighted by the Gaussian and normalised so each object weighs 1 in total. A peak
the heatmap puts one cell off the centre still decodes the right box. Where objects overlap,
the smaller box owns the cell (boxes are written largest first).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from conesight_train.detector.model import ASPECT_PRIOR, STRIDE_PX

SIGMA_FRACTION = 1.0 / 6.0
MIN_SIGMA_CELLS = 0.4
MAX_OBJECTS = 160
MIN_BOX_PX = 2.0
DENSE_MIN_GAUSS = 0.3


@dataclass(frozen=True)
class DetectorTargets:
    """Per-image targets; the first objects entries of the per-object arrays are real."""

    heat: np.ndarray  # float32 [C, h, w]
    ignore: np.ndarray  # float32 [h, w], 1 where negatives do not count
    index: np.ndarray  # int64 [MAX_OBJECTS], flattened cell y * w + x
    mask: np.ndarray  # float32 [MAX_OBJECTS]
    regression: np.ndarray  # float32 [MAX_OBJECTS, 4] (dx, dy, log_h, log_aspect)
    dense_regression: np.ndarray  # float32 [4, h, w], the owning object's box per cell
    dense_weight: np.ndarray  # float32 [h, w], 0 where no object regresses
    dense_class: np.ndarray  # int64 [h, w], the owning object's class, -1 where none


def encode(
    boxes_px: np.ndarray,
    classes: np.ndarray,
    class_count: int,
    input_hw: tuple[int, int],
    difficult: np.ndarray | None = None,
) -> DetectorTargets:
    """Targets for boxes [M, 4] of `classes` [M] on an input of `input_hw` (H, W).

    `difficult` [M] boxes are not positives; their cells are left out of the negatives."""
    h, w = input_hw[0] // STRIDE_PX, input_hw[1] // STRIDE_PX
    heat = np.zeros((class_count, h, w), np.float32)
    ignore = np.zeros((h, w), np.float32)
    index = np.zeros(MAX_OBJECTS, np.int64)
    mask = np.zeros(MAX_OBJECTS, np.float32)
    regression = np.zeros((MAX_OBJECTS, 4), np.float32)
    dense = np.zeros((4, h, w), np.float32)
    dense_weight = np.zeros((h, w), np.float32)
    dense_class = np.full((h, w), -1, np.int64)
    boxes = np.asarray(boxes_px, np.float64).reshape(-1, 4)
    classes = np.asarray(classes, np.int64).reshape(-1)
    hard = np.zeros(len(classes), bool) if difficult is None else np.asarray(difficult, bool)
    count = 0
    # Largest first, so a smaller (nearer-the-camera-than-it-looks or occluding) box owns the
    # dense-regression cells they share.
    areas = (boxes[:, 2] - boxes[:, 0]) * (boxes[:, 3] - boxes[:, 1])
    order = np.argsort(-areas, kind="stable")
    for box, cls, is_hard in zip(boxes[order], classes[order], hard[order], strict=True):
        bw, bh = box[2] - box[0], box[3] - box[1]
        u, v = (box[0] + box[2]) / 2 / STRIDE_PX, (box[1] + box[3]) / 2 / STRIDE_PX
        cx, cy = int(np.floor(u)), int(np.floor(v))
        if not (0 <= cx < w and 0 <= cy < h) or bw <= 0 or bh <= 0:
            continue
        if is_hard or min(bw, bh) < MIN_BOX_PX:
            x0 = max(min(int(box[0] // STRIDE_PX), cx - 1), 0)
            y0 = max(min(int(box[1] // STRIDE_PX), cy - 1), 0)
            x1 = max(int(np.ceil(box[2] / STRIDE_PX)), cx + 2)
            y1 = max(int(np.ceil(box[3] / STRIDE_PX)), cy + 2)
            ignore[y0:y1, x0:x1] = 1.0
            continue
        sx = max(MIN_SIGMA_CELLS, SIGMA_FRACTION * bw / STRIDE_PX)
        sy = max(MIN_SIGMA_CELLS, SIGMA_FRACTION * bh / STRIDE_PX)
        rx, ry = int(np.ceil(3 * sx)), int(np.ceil(3 * sy))
        x0, x1 = max(cx - rx, 0), min(cx + rx + 1, w)
        y0, y1 = max(cy - ry, 0), min(cy + ry + 1, h)
        ys, xs = np.mgrid[y0:y1, x0:x1]
        gauss = np.exp(-((xs - cx) ** 2) / (2 * sx**2) - ((ys - cy) ** 2) / (2 * sy**2))
        np.maximum(heat[cls, y0:y1, x0:x1], gauss.astype(np.float32), out=heat[cls, y0:y1, x0:x1])
        own = gauss >= DENSE_MIN_GAUSS
        weight = np.where(own, gauss, 0.0)
        weight /= weight.sum()
        sub = (slice(y0, y1), slice(x0, x1))
        dense[0][sub] = np.where(own, u - xs - 0.5, dense[0][sub])
        dense[1][sub] = np.where(own, v - ys - 0.5, dense[1][sub])
        dense[2][sub] = np.where(own, np.log(bh / STRIDE_PX), dense[2][sub])
        dense[3][sub] = np.where(own, np.log(bw / bh / ASPECT_PRIOR), dense[3][sub])
        dense_weight[sub] = np.where(own, weight, dense_weight[sub])
        dense_class[sub] = np.where(own, cls, dense_class[sub])
        if count < MAX_OBJECTS:
            index[count] = cy * w + cx
            mask[count] = 1.0
            regression[count] = (
                u - cx - 0.5,
                v - cy - 0.5,
                np.log(bh / STRIDE_PX),
                np.log(bw / bh / ASPECT_PRIOR),
            )
            count += 1
    return DetectorTargets(heat, ignore, index, mask, regression, dense, dense_weight, dense_class)
