"""The detector's input scheme, defined once: the **whole frame**, area-resized into a fixed
input and padded, so cones are found wherever they are, at any camera pitch or mount, with no
calibration at all (crates/conesight-detect `preprocess.rs` is the same rule in Rust).

    scale     s = min(input_width / frame_width, input_height / frame_height)
    resized   round(frame_width * s) x round(frame_height * s) px, cv2.INTER_AREA when
              shrinking (the area mean; for an integer factor the plain block mean),
              INTER_LINEAR when enlarging
    placed    at the input's top-left corner; the rest filled with grey FILL (114, as
              Ultralytics pads)
    input     float32 RGB, raw 0..255, channel-first [3, input_height, input_width]

Defaults: 960x608, so a 1920x1200 frame is exactly box-averaged 2x2 (960x600 + 8 rows of
fill) and a 1920x1080 frame gives 960x540. Coordinates are continuous (the frame spans [0, W]
x [0, H]): input = frame * (sx, sy), with sx = resized_width / frame_width and likewise sy
(equal to s up to rounding).
"""

from __future__ import annotations

import argparse
from dataclasses import asdict, dataclass

import cv2
import numpy as np

FILL = 114


@dataclass(frozen=True)
class FrameInputParams:
    """The network's input size (defaults: the shipped configuration)."""

    input_width_px: int = 960
    input_height_px: int = 608

    def __post_init__(self) -> None:
        if (
            self.input_width_px % 32
            or self.input_height_px % 32
            or min(self.input_width_px, self.input_height_px) <= 0
        ):
            raise ValueError(
                f"input {self.input_width_px}x{self.input_height_px}: width and height must be "
                "positive multiples of 32 (the network's stride)"
            )

    def resized_wh(self, frame_hw: tuple[int, int]) -> tuple[int, int]:
        """(width, height) of the frame once resized into the input."""
        h, w = frame_hw
        if h <= 0 or w <= 0:
            raise ValueError(f"empty frame {w}x{h}")
        s = min(self.input_width_px / w, self.input_height_px / h)
        return (
            min(max(1, round(w * s)), self.input_width_px),
            min(max(1, round(h * s)), self.input_height_px),
        )

    def scale_xy(self, frame_hw: tuple[int, int]) -> tuple[float, float]:
        """(sx, sy): input pixels per frame pixel along x and y."""
        rw, rh = self.resized_wh(frame_hw)
        return rw / frame_hw[1], rh / frame_hw[0]

    def to_dict(self) -> dict[str, int]:
        """The fields for checkpoints and cards."""
        return asdict(self)

    @classmethod
    def parse(cls, text: str) -> FrameInputParams:
        """`WIDTHxHEIGHT` (e.g. `1280x800`, CLI flags); ValueError naming the text otherwise."""
        parts = text.lower().split("x")
        if len(parts) != 2 or not all(p.strip().isdigit() for p in parts):
            raise ValueError(f"input size {text!r}: expected WIDTHxHEIGHT, e.g. 1280x800")
        return cls(int(parts[0]), int(parts[1]))


def input_size_arg(text: str) -> FrameInputParams:
    """argparse type for `--input-size WIDTHxHEIGHT` (the error names the flag's rule)."""
    try:
        return FrameInputParams.parse(text)
    except ValueError as err:
        raise argparse.ArgumentTypeError(str(err)) from None


def resize_area(image: np.ndarray, size_wh: tuple[int, int]) -> np.ndarray:
    """HxWx3 uint8 -> the area mean (shrinking) or bilinear (enlarging) image of `size_wh`,
    uint8 rounded, computed on float32 as the Rust runtime does."""
    h, w = image.shape[:2]
    if (w, h) == tuple(size_wh):
        return image
    shrink = size_wh[0] <= w and size_wh[1] <= h
    resized = cv2.resize(
        image.astype(np.float32),
        size_wh,
        interpolation=cv2.INTER_AREA if shrink else cv2.INTER_LINEAR,
    )
    return np.clip(resized + 0.5, 0, 255).astype(np.uint8)


def frame_to_input(
    image_rgb: np.ndarray, params: FrameInputParams
) -> tuple[np.ndarray, tuple[float, float]]:
    """(input float32 [3, H, W], (sx, sy)) for an HxWx3 uint8 RGB frame (module docs)."""
    rw, rh = params.resized_wh(image_rgb.shape[:2])
    canvas = np.full((params.input_height_px, params.input_width_px, 3), FILL, np.uint8)
    canvas[:rh, :rw] = resize_area(image_rgb, (rw, rh))
    sx, sy = rw / image_rgb.shape[1], rh / image_rgb.shape[0]
    return np.ascontiguousarray(canvas.transpose(2, 0, 1), dtype=np.float32), (sx, sy)


def boxes_to_frame(boxes_px: np.ndarray, scale_xy: tuple[float, float]) -> np.ndarray:
    """Boxes [D, 4] (x0, y0, x1, y1) from continuous input to continuous frame pixels."""
    out = np.asarray(boxes_px, np.float64).copy()
    out[:, [0, 2]] /= scale_xy[0]
    out[:, [1, 3]] /= scale_xy[1]
    return out
