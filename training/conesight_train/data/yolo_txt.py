"""Reader for YOLO txt box labels (one file per image, `class cx cy w h` per line, normalised).

Coordinates are fractions of the image width and height; this reader returns boxes in
continuous pixel edges (conesight/OpenCV convention) given the image size. Blank lines are
allowed; anything else malformed (wrong field count, non-numbers, class ids out of range,
coordinates outside [0, 1], empty boxes) raises `LabelError` with the line.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from conesight_train.data.errors import LabelError

# conesight's detector classes, in class-id order.
CONE_CLASSES: tuple[str, ...] = ("blue", "yellow", "orange", "large_orange")
# Coordinates may exceed [0, 1] by this much (labelling tools round).
COORD_TOLERANCE = 1e-3


@dataclass(frozen=True)
class YoloBox:
    """One labelled box in pixels (continuous edges)."""

    class_id: int
    x_min_px: float
    y_min_px: float
    x_max_px: float
    y_max_px: float
    line: int


def read_yolo_txt(
    path: str | Path, width_px: int, height_px: int, class_count: int = len(CONE_CLASSES)
) -> list[YoloBox]:
    """Reads one YOLO label file for an image of `width_px` x `height_px`."""
    path = Path(path)
    boxes = []
    for line, text in enumerate(path.read_text(encoding="utf-8").splitlines(), start=1):
        fields = text.split()
        if not fields:
            continue
        if len(fields) != 5:
            raise LabelError(path, f"expected 'class cx cy w h', got {len(fields)} fields", line)
        try:
            class_id = int(fields[0])
            cx, cy, w, h = (float(v) for v in fields[1:])
        except ValueError as err:
            raise LabelError(path, f"not numbers: {text.strip()!r}", line) from err
        if not 0 <= class_id < class_count:
            raise LabelError(path, f"class id {class_id} outside 0..{class_count - 1}", line)
        values = np.array([cx, cy, w, h])
        if (
            not np.all(np.isfinite(values))
            or np.any(values < -COORD_TOLERANCE)
            or np.any(values > 1 + COORD_TOLERANCE)
        ):
            raise LabelError(
                path, f"coordinates must be fractions in [0, 1]: {text.strip()!r}", line
            )
        if w <= 0 or h <= 0:
            raise LabelError(path, f"empty box (w={w}, h={h})", line)
        boxes.append(
            YoloBox(
                class_id,
                (cx - w / 2) * width_px - 0.5,
                (cy - h / 2) * height_px - 0.5,
                (cx + w / 2) * width_px - 0.5,
                (cy + h / 2) * height_px - 0.5,
                line,
            )
        )
    return boxes
