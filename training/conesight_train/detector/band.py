"""The detector's input scheme, defined once: a horizon band, box-averaged by an integer factor.

Cones stand on the ground and are shorter than the camera is high (~1 m), so with a roughly
level camera every cone lies below the horizon row: a 0.33 m cone at 5 m spans rows ~276-410 px
below it (f = 2048 px), at 30 m a few px. The detector therefore sees only a band of rows:

    rows [top, top + factor * input_height) of the frame, all columns,
    each input pixel = the mean of a factor x factor block of frame pixels (box filter),
    float32 RGB, raw 0..255, channel-first [1, 3, input_height, input_width].

`top` is the band's first row clamped to [0, frame_height - factor * input_height] (so a
1080-row frame uses its lowest rows when the band would overrun). The first row comes from
the camera calibration when known: `top = horizon row - HORIZON_MARGIN_PX` (`band_top_from`;
the horizon row is where the vehicle's forward direction projects, so pitch moves the band
with the horizon); otherwise `band_top_px`, the level paper camera's value. The 728 rows below
the horizon reach ground points at f h / 728 = 2.8 m (f = 2048 px, h = 1 m; 3.5 m for the
renderer's highest mount, 1.25 m): with 640 rows, 3 of 40 cones within 20 m in rendered frames
reached below the band. The frame width must equal `factor * input_width`. Defaults: 1920x1200
frames, 768 band rows from 560 (40 px above the horizon of a level camera at cy = 600; clamped
to 432..1200), factor 2 -> a 960x384 input (0.37 MPx).

Coordinates follow OpenCV (pixel i centred at i; box edges are continuous). Input -> frame:
`x = (x_in + 0.5) * factor - 0.5`, `y = (y_in + 0.5) * factor - 0.5 + top`.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import cv2
import numpy as np

# Rows kept above the horizon: roll (0.02 rad moves the horizon +-19 px at the image edges),
# calibration error, and bumps.
HORIZON_MARGIN_PX = 40


def horizon_row_px(fy_px: float, cy_px: float, camera_from_vehicle_rotation: np.ndarray) -> float:
    """Image row of the horizon at the principal point: the projection of the vehicle's
    forward direction (x, REP-103) into the camera (OpenCV axes)."""
    forward = np.asarray(camera_from_vehicle_rotation, np.float64) @ np.array([1.0, 0.0, 0.0])
    if forward[2] <= 1e-6:
        raise ValueError("the camera does not look forward: no horizon in the image")
    return float(cy_px + fy_px * forward[1] / forward[2])


def band_top_from(horizon_px: float) -> int:
    """The band's first row for a horizon row (before clamping into the frame)."""
    return round(horizon_px) - HORIZON_MARGIN_PX


@dataclass(frozen=True)
class BandParams:
    """Band rows and the downsampling factor (defaults: the shipped configuration)."""

    band_top_px: int = 560
    input_width_px: int = 960
    input_height_px: int = 384
    factor: int = 2

    @property
    def band_height_px(self) -> int:
        """Frame rows covered by the band."""
        return self.factor * self.input_height_px

    @property
    def frame_width_px(self) -> int:
        """The frame width this band needs."""
        return self.factor * self.input_width_px

    def top_for(self, frame_height_px: int, top_px: int | None = None) -> int:
        """The band's first frame row for a frame of this height (clamped); `top_px` (from the
        horizon) replaces `band_top_px` when given."""
        if frame_height_px < self.band_height_px:
            raise ValueError(
                f"frame height {frame_height_px} px is below the band height "
                f"{self.band_height_px} px (input height {self.input_height_px} x factor "
                f"{self.factor}); use a smaller input height or factor"
            )
        top = self.band_top_px if top_px is None else top_px
        return min(max(top, 0), frame_height_px - self.band_height_px)

    def to_dict(self) -> dict[str, int]:
        """The fields for a model card."""
        return asdict(self)


def band_to_input(frame_rgb: np.ndarray, band: BandParams, top_px: int | None = None) -> np.ndarray:
    """HxWx3 uint8 frame -> float32 [3, input_height, input_width] (see the module docs).

    `top_px` is the band's first row, used as is (it must keep the band in the frame);
    None means `band.top_for(height)`.
    """
    if frame_rgb.ndim != 3 or frame_rgb.shape[2] != 3:
        raise ValueError(f"expected an HxWx3 RGB frame, got shape {frame_rgb.shape}")
    height, width = frame_rgb.shape[:2]
    if width != band.frame_width_px:
        raise ValueError(
            f"frame width {width} px does not match the band's {band.frame_width_px} px "
            f"(input width {band.input_width_px} x factor {band.factor})"
        )
    top = band.top_for(height) if top_px is None else top_px
    if not 0 <= top <= height - band.band_height_px:
        raise ValueError(f"band top {top} px puts the band outside a {height}-row frame")
    rows = frame_rgb[top : top + band.band_height_px].astype(np.float32)
    # INTER_AREA with an integer factor on float32 is the exact block mean.
    mean = cv2.resize(
        rows, (band.input_width_px, band.input_height_px), interpolation=cv2.INTER_AREA
    )
    return np.ascontiguousarray(mean.transpose(2, 0, 1))


def input_from_frame(boxes_px: np.ndarray, band: BandParams, top_px: int) -> np.ndarray:
    """Boxes [..., 4] (x_min, y_min, x_max, y_max) from frame to input pixels."""
    boxes = np.asarray(boxes_px, dtype=np.float64).copy()
    boxes[..., [1, 3]] -= top_px
    return (boxes + 0.5) / band.factor - 0.5


def frame_from_input(boxes_px: np.ndarray, band: BandParams, top_px: int) -> np.ndarray:
    """Boxes [..., 4] from input back to frame pixels."""
    boxes = (np.asarray(boxes_px, dtype=np.float64) + 0.5) * band.factor - 0.5
    boxes[..., [1, 3]] += top_px
    return boxes
