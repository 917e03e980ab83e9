"""Boxes -> CenterNet training targets at the output stride.

Heat coordinates follow the OpenCV convention at 1/STRIDE scale: `u = (x + 0.5) / STRIDE - 0.5`.
A box's centre falls in cell `round(u)`; the target there is 1 with an elliptical Gaussian
around it (sigma = SIGMA_FRACTION x the box's heat-space width and height, at least
MIN_SIGMA_CELLS), the max over boxes of each class; the size target is log(width, height) in
heat cells, the offset target the centre minus its cell.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

STRIDE_PX = 4
SIGMA_FRACTION = 1.0 / 6.0
MIN_SIGMA_CELLS = 0.5
MAX_OBJECTS = 128


@dataclass(frozen=True)
class DetectionTargets:
    """Per-image targets: heat [C, h, w]; the first `count` entries of the rest are objects."""

    heat: np.ndarray  # float32 [C, h, w]
    index: np.ndarray  # int64 [MAX_OBJECTS], flattened cell index y * w + x
    mask: np.ndarray  # float32 [MAX_OBJECTS], 1 for real objects
    log_size: np.ndarray  # float32 [MAX_OBJECTS, 2], log(width, height) in cells
    offset: np.ndarray  # float32 [MAX_OBJECTS, 2], centre - cell


def encode(
    boxes_px: np.ndarray, classes: np.ndarray, class_count: int, input_hw: tuple[int, int]
) -> DetectionTargets:
    """Targets for boxes [M, 4] (input-pixel edges) of `classes` [M] on an input of `input_hw`."""
    height, width = input_hw[0] // STRIDE_PX, input_hw[1] // STRIDE_PX
    heat = np.zeros((class_count, height, width), np.float32)
    index = np.zeros(MAX_OBJECTS, np.int64)
    mask = np.zeros(MAX_OBJECTS, np.float32)
    log_size = np.zeros((MAX_OBJECTS, 2), np.float32)
    offset = np.zeros((MAX_OBJECTS, 2), np.float32)
    ys, xs = np.mgrid[0:height, 0:width].astype(np.float32)
    count = 0
    for box, cls in zip(np.asarray(boxes_px, np.float64), np.asarray(classes), strict=True):
        w_cells = (box[2] - box[0]) / STRIDE_PX
        h_cells = (box[3] - box[1]) / STRIDE_PX
        if w_cells <= 0 or h_cells <= 0:
            continue
        centre = (
            ((box[0] + box[2]) / 2 + 0.5) / STRIDE_PX - 0.5,
            ((box[1] + box[3]) / 2 + 0.5) / STRIDE_PX - 0.5,
        )
        cx, cy = round(centre[0]), round(centre[1])
        if not (0 <= cx < width and 0 <= cy < height):
            continue
        sx = max(MIN_SIGMA_CELLS, SIGMA_FRACTION * w_cells)
        sy = max(MIN_SIGMA_CELLS, SIGMA_FRACTION * h_cells)
        gauss = np.exp(-((xs - cx) ** 2) / (2 * sx**2) - ((ys - cy) ** 2) / (2 * sy**2))
        np.maximum(heat[int(cls)], gauss, out=heat[int(cls)])
        if count < MAX_OBJECTS:
            index[count] = cy * width + cx
            mask[count] = 1.0
            log_size[count] = (np.log(w_cells), np.log(h_cells))
            offset[count] = (centre[0] - cx, centre[1] - cy)
            count += 1
    return DetectionTargets(heat, index, mask, log_size, offset)
