"""The keypoint patch rule (box -> square patch), mirrored from conesight-vision's `crop.rs`.

The Rust module is the definition; this file follows it line by line so that training patches,
the renderer's patch writer and the keypoint service agree:

1. Centre (cx, cy) = box centre; w, h = box width and height (both > 0). Boxes are continuous
   edges: a box covering pixel columns 10..=19 has x_min_px = 9.5, x_max_px = 19.5.
2. Side S = max(w, h) * (1 + 2 * margin_fraction).
3. With s = S / N (N = patch side), patch pixel (u, v) is the bilinear sample of the image at
   x = x0 + (u + 0.5) * s, y = y0 + (v + 0.5) * s, x0 = cx - S/2, y0 = cy - S/2; neighbours
   outside the image read as `fill`.
4. Keypoints map by u = (x - x0) / s - 0.5 and back by x = x0 + (u + 0.5) * s.

`crop_patch` reproduces the Rust sampler (float32 weights, round half away from zero) so the two
agree to the grey level; `crop_patch_opencv` is the faster `cv2.warpAffine` equivalent (OpenCV
quantises the weights to 1/32, so it differs by up to 1/64 of the contrast between neighbouring
pixels: one grey level on smooth images, a few on pixel noise).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

PATCH_SIZE_PX = 80
MARGIN_FRACTION = 0.1


class CropError(ValueError):
    """A crop could not be made (empty or non-finite box, zero patch size)."""


@dataclass(frozen=True)
class PixelBox:
    """An axis-aligned box in continuous pixel coordinates (edges, OpenCV convention)."""

    x_min_px: float
    y_min_px: float
    x_max_px: float
    y_max_px: float

    @staticmethod
    def from_pixel_range(col_min: int, row_min: int, col_max: int, row_max: int) -> PixelBox:
        """The box covering the inclusive integer pixel range."""
        return PixelBox(col_min - 0.5, row_min - 0.5, col_max + 0.5, row_max + 0.5)

    @staticmethod
    def whole_image(width_px: int, height_px: int) -> PixelBox:
        """The box covering every pixel of a `width_px` x `height_px` image."""
        return PixelBox.from_pixel_range(0, 0, width_px - 1, height_px - 1)

    @property
    def width_px(self) -> float:
        return self.x_max_px - self.x_min_px

    @property
    def height_px(self) -> float:
        return self.y_max_px - self.y_min_px

    def is_valid(self) -> bool:
        values = (self.x_min_px, self.y_min_px, self.x_max_px, self.y_max_px)
        return bool(np.all(np.isfinite(values))) and self.width_px > 0 and self.height_px > 0


@dataclass(frozen=True)
class CropParams:
    """Tuning of the crop rule (defaults equal `conesight_vision::CropParams::default()`)."""

    patch_size_px: int = PATCH_SIZE_PX
    margin_fraction: float = MARGIN_FRACTION
    fill: tuple[int, int, int] = (0, 0, 0)


@dataclass(frozen=True)
class PatchTransform:
    """The similarity between a patch and the image it was cut from."""

    x0_px: float
    y0_px: float
    scale: float  # image pixels per patch pixel
    patch_size_px: int

    @staticmethod
    def for_box(bbox: PixelBox, params: CropParams | None = None) -> PatchTransform:
        params = params or CropParams()
        if not bbox.is_valid():
            raise CropError(
                f"box ({bbox.x_min_px}, {bbox.y_min_px})-({bbox.x_max_px}, {bbox.y_max_px}) "
                "is empty or not finite; pass edges with x_min < x_max and y_min < y_max"
            )
        if params.patch_size_px < 1:
            raise CropError("patch_size_px must be at least 1")
        side = max(bbox.width_px, bbox.height_px) * (1.0 + 2.0 * params.margin_fraction)
        cx = 0.5 * (bbox.x_min_px + bbox.x_max_px)
        cy = 0.5 * (bbox.y_min_px + bbox.y_max_px)
        return PatchTransform(
            x0_px=cx - 0.5 * side,
            y0_px=cy - 0.5 * side,
            scale=side / params.patch_size_px,
            patch_size_px=params.patch_size_px,
        )

    def patch_from_image(self, points_in_image: np.ndarray) -> np.ndarray:
        """Patch coordinates of image points, shape (..., 2)."""
        points = np.asarray(points_in_image, dtype=np.float64)
        origin = np.array([self.x0_px, self.y0_px])
        return (points - origin) / self.scale - 0.5

    def image_from_patch(self, points_in_patch: np.ndarray) -> np.ndarray:
        """Image coordinates of patch points, shape (..., 2)."""
        points = np.asarray(points_in_patch, dtype=np.float64)
        origin = np.array([self.x0_px, self.y0_px])
        return origin + (points + 0.5) * self.scale

    def opencv_matrix(self) -> np.ndarray:
        """OpenCV's `warpAffine` matrix (image -> patch), 2x3."""
        inv = 1.0 / self.scale
        return np.array(
            [[inv, 0.0, -self.x0_px * inv - 0.5], [0.0, inv, -self.y0_px * inv - 0.5]],
            dtype=np.float64,
        )


def bilinear_rgb(image: np.ndarray, xs: np.ndarray, ys: np.ndarray, fill: np.ndarray) -> np.ndarray:
    """Bilinear samples of an HxWx3 uint8 image at float64 points, as float32.

    Mirrors Rust's `conesight_vision::sample::bilinear_rgb` operation by operation.
    """
    height, width = image.shape[:2]
    x0 = np.floor(xs)
    y0 = np.floor(ys)
    fx = (xs - x0).astype(np.float32)[..., None]
    fy = (ys - y0).astype(np.float32)[..., None]
    ix = x0.astype(np.int64)
    iy = y0.astype(np.int64)
    fill32 = np.asarray(fill, dtype=np.float32)

    def fetch(cx: np.ndarray, cy: np.ndarray) -> np.ndarray:
        inside = (cx >= 0) & (cy >= 0) & (cx < width) & (cy < height)
        values = image[np.clip(cy, 0, height - 1), np.clip(cx, 0, width - 1)].astype(np.float32)
        return np.where(inside[..., None], values, fill32)

    p00 = fetch(ix, iy)
    p10 = fetch(ix + 1, iy)
    p01 = fetch(ix, iy + 1)
    p11 = fetch(ix + 1, iy + 1)
    top = p00 + (p10 - p00) * fx
    bottom = p01 + (p11 - p01) * fx
    return top + (bottom - top) * fy


def crop_patch(
    image: np.ndarray, bbox: PixelBox, params: CropParams | None = None
) -> tuple[np.ndarray, PatchTransform]:
    """Cuts the NxN RGB uint8 patch for `bbox` out of an HxWx3 uint8 image (exact Rust mirror)."""
    params = params or CropParams()
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype != np.uint8:
        raise CropError(f"expected an HxWx3 uint8 image, got shape {image.shape} {image.dtype}")
    transform = PatchTransform.for_box(bbox, params)
    n = params.patch_size_px
    grid = np.arange(n, dtype=np.float64)
    xs = transform.x0_px + (grid[None, :] + 0.5) * transform.scale
    ys = transform.y0_px + (grid[:, None] + 0.5) * transform.scale
    xs, ys = np.broadcast_to(xs, (n, n)), np.broadcast_to(ys, (n, n))
    values = bilinear_rgb(image, xs, ys, np.asarray(params.fill))
    # Rust's f32::round rounds half away from zero, numpy's round half to even: fix the halves.
    floor = np.floor(values)
    rounded = np.where(values - floor == np.float32(0.5), floor + 1, np.round(values))
    patch = np.clip(rounded, 0, 255).astype(np.uint8)
    return patch, transform


def crop_patch_opencv(
    image: np.ndarray, bbox: PixelBox, params: CropParams | None = None
) -> tuple[np.ndarray, PatchTransform]:
    """`crop_patch` through `cv2.warpAffine` (faster; see the module docs for the difference)."""
    params = params or CropParams()
    transform = PatchTransform.for_box(bbox, params)
    n = params.patch_size_px
    patch = cv2.warpAffine(
        image,
        transform.opencv_matrix(),
        (n, n),
        flags=cv2.INTER_LINEAR,
        borderMode=cv2.BORDER_CONSTANT,
        borderValue=tuple(int(c) for c in params.fill),
    )
    return patch, transform
