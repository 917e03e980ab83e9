"""Frame -> detector input, defined once: scale to fit, pad right/bottom with 0.

The detector takes `float32 [N, 3, H, W]` RGB with raw 0..255 values (normalised inside the
network, like the keypoint networks). A frame of width w and height h is resized by
`s = min(W / w, H / h)` (area interpolation) into the top-left corner; boxes map by
`x_in = (x + 0.5) * s - 0.5` (OpenCV pixel convention) and back by `x = (x_in + 0.5) / s - 0.5`.
The paper's 1920x1200 camera fits 640x400 exactly (s = 1/3).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

INPUT_WIDTH_PX = 640
INPUT_HEIGHT_PX = 400


@dataclass(frozen=True)
class FrameTransform:
    """Frame -> input scaling (`scale` input pixels per frame pixel)."""

    scale: float

    def input_from_frame(self, boxes_px: np.ndarray) -> np.ndarray:
        """Boxes [..., 4] (x_min, y_min, x_max, y_max edges) from frame to input pixels."""
        return (np.asarray(boxes_px, dtype=np.float64) + 0.5) * self.scale - 0.5

    def frame_from_input(self, boxes_px: np.ndarray) -> np.ndarray:
        """Boxes [..., 4] from input back to frame pixels."""
        return (np.asarray(boxes_px, dtype=np.float64) + 0.5) / self.scale - 0.5


def frame_to_input(
    frame_rgb: np.ndarray, width_px: int = INPUT_WIDTH_PX, height_px: int = INPUT_HEIGHT_PX
) -> tuple[np.ndarray, FrameTransform]:
    """HxWx3 uint8 RGB frame -> (height_px x width_px x 3 uint8 input, transform)."""
    if frame_rgb.ndim != 3 or frame_rgb.shape[2] != 3:
        raise ValueError(f"expected an HxWx3 RGB frame, got shape {frame_rgb.shape}")
    h, w = frame_rgb.shape[:2]
    scale = min(width_px / w, height_px / h)
    new_w, new_h = min(width_px, round(w * scale)), min(height_px, round(h * scale))
    resized = cv2.resize(frame_rgb, (new_w, new_h), interpolation=cv2.INTER_AREA)
    canvas = np.zeros((height_px, width_px, 3), dtype=np.uint8)
    canvas[:new_h, :new_w] = resized
    return canvas, FrameTransform(scale)
