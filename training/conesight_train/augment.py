"""Augmentation aimed at real photographs, on top of the renderer's own variety.

Geometric (patch level, keypoints follow): rotation, scale and shift standing in for detector
box jitter and for other labellers' framing (the paper's floor: rotation +-15 degrees, box scale
0.8-1.5x, translation up to 50 % of the box edge; a draw that would put a keypoint where the
network cannot reach it, closer than `edge_px` to the patch border, is drawn again, up to
`geometric_tries` times, else the patch stays as it is), horizontal mirror (left/right
keypoints swap), truncation (a band at one side replaced by the crop rule's fill, as when a
cone leaves the image), occlusion from below (the cone's lower part behind a flat occluder,
keypoints where they truly are), a neighbouring cone pasted at a side.
Photometric: exposure (one gain for the whole patch, under- and over-exposed, with a glare
wash), per-channel colour gain and offset, gamma, Gaussian or motion blur, sensor noise, JPEG
re-compression, and low resolution (the patch taken down until the cone is 15-40 px tall and
blown up again, as the crop rule does for a far cone). Every draw comes from the Generator
passed in, so results are seeded.

Box jitter done here re-samples the patch, so context outside it is mirrored from inside
(BORDER_REFLECT_101); jittering the box in the full image at render time
(`conesight sim --patch-jitter`) is better where available.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from conesight_train.data.patches import KeypointPatch, PatchSource
from conesight_train.keypoints import MIRROR_PERMUTATION


@dataclass(frozen=True)
class AugmentParams:
    """Probabilities and ranges of each augmentation (defaults: the training configuration)."""

    # Content scale: a box 1.5x to 0.8x the labelled one shows the cone 0.67x to 1.25x as large.
    # Rendered apexes already sit 3 px below the patch top, so most draws above 1.05 are
    # redrawn (the production network's soft-argmax cannot reach above 1.5 px).
    scale_range: tuple[float, float] = (0.67, 1.25)
    rotation_deg: float = 15.0
    # Of the patch side, each axis: 0.4 of the side is 50 % of a box edge (the patch is 1.2x
    # the box's longer side).
    shift_fraction: float = 0.4
    edge_px: float = 1.5
    geometric_tries: int = 8
    p_geometric: float = 0.8
    p_mirror: float = 0.5
    p_truncate: float = 0.05
    truncate_max_fraction: float = 0.25  # of the patch side
    p_neighbour: float = 0.1
    p_colour: float = 0.8
    colour_gain_range: tuple[float, float] = (0.8, 1.2)
    colour_offset_max: float = 20.0
    p_gamma: float = 0.5
    gamma_range: tuple[float, float] = (0.7, 1.4)
    p_blur: float = 0.4
    blur_sigma_max_px: float = 1.2
    motion_blur_max_px: int = 5
    p_noise: float = 0.5
    noise_sigma_max: float = 8.0
    p_jpeg: float = 0.4
    jpeg_quality_range: tuple[int, int] = (30, 95)
    # Exposure: one gain for all channels (a dark or a bright camera), and a glare wash.
    p_exposure: float = 0.3
    exposure_gain_range: tuple[float, float] = (0.45, 1.8)
    p_glare: float = 0.1
    glare_max: float = 90.0
    # Low resolution: the cone's height in the source (the patch shows it ~65 px tall).
    p_low_resolution: float = 0.3
    low_resolution_cone_px: tuple[float, float] = (15.0, 40.0)
    # Occlusion from below (a low wall, the car's nose, a nearer cone's tip): the lower part of
    # the cone, up to this share of its apex-to-base height, hidden behind a flat occluder whose
    # top edge may slope; the keypoints keep their true places (amodal), so the network learns
    # to put a hidden base where the stripes and the apex say it is.
    p_occlude: float = 0.15
    occlude_share_range: tuple[float, float] = (0.15, 0.55)


def _geometric(
    patch: np.ndarray, keypoints: np.ndarray, rng: np.random.Generator, p: AugmentParams
) -> tuple[np.ndarray, np.ndarray]:
    n = patch.shape[0]
    centre = (n - 1) / 2.0
    low, high = p.edge_px, n - 1 - p.edge_px
    for _ in range(p.geometric_tries):
        scale = rng.uniform(*p.scale_range)
        shift = rng.uniform(-p.shift_fraction, p.shift_fraction, size=2) * n
        angle = np.deg2rad(rng.uniform(-p.rotation_deg, p.rotation_deg))
        linear = scale * np.array([[np.cos(angle), -np.sin(angle)], [np.sin(angle), np.cos(angle)]])
        offset = centre - linear @ np.array([centre, centre]) + shift
        moved = keypoints @ linear.T + offset
        if moved.min() < low or moved.max() > high:
            continue
        matrix = np.hstack([linear, offset[:, None]])
        out = cv2.warpAffine(
            patch, matrix, (n, n), flags=cv2.INTER_LINEAR, borderMode=cv2.BORDER_REFLECT_101
        )
        return out, moved
    return patch, keypoints


def _mirror(patch: np.ndarray, keypoints: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    n = patch.shape[1]
    flipped = keypoints[list(MIRROR_PERMUTATION)].copy()
    flipped[:, 0] = (n - 1) - flipped[:, 0]
    return np.ascontiguousarray(patch[:, ::-1]), flipped


def _truncate(patch: np.ndarray, rng: np.random.Generator, p: AugmentParams) -> np.ndarray:
    n = patch.shape[0]
    width = int(rng.integers(1, max(2, int(p.truncate_max_fraction * n))))
    out = patch.copy()
    side = int(rng.integers(4))
    if side == 0:
        out[:, :width] = 0
    elif side == 1:
        out[:, n - width :] = 0
    elif side == 2:
        out[:width] = 0
    else:
        out[n - width :] = 0
    return out


def _occlude(
    patch: np.ndarray, keypoints: np.ndarray, rng: np.random.Generator, p: AugmentParams
) -> np.ndarray:
    """Hides the cone's lower part behind a flat, noisy occluder (module docs)."""
    n = patch.shape[0]
    apex_y = float(keypoints[0, 1])
    base_y = float((keypoints[3, 1] + keypoints[6, 1]) / 2)
    height = base_y - apex_y
    if height <= 2:
        return patch
    top = base_y - rng.uniform(*p.occlude_share_range) * height
    slope = rng.uniform(-0.15, 0.15)
    rows = np.arange(n, dtype=np.float32)[:, None]
    cols = np.arange(n, dtype=np.float32)[None, :]
    hidden = rows >= top + slope * (cols - n / 2)
    colour = rng.uniform(20, 200, size=3).astype(np.float32)
    texture = rng.normal(0.0, rng.uniform(2, 15), size=(n, n, 1)).astype(np.float32)
    occluder = np.clip(colour + texture, 0, 255).astype(np.uint8)
    out = patch.copy()
    out[hidden] = occluder[hidden]
    return out


def _neighbour(patch: np.ndarray, other: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Pastes the central vertical strip of `other` (its cone) shrunk, at one side of `patch`."""
    n = patch.shape[0]
    scale = rng.uniform(0.5, 1.0)
    size = max(2, int(n * scale))
    small = cv2.resize(other, (size, size), interpolation=cv2.INTER_AREA)
    strip_w = max(1, int(rng.uniform(0.12, 0.25) * n))
    start = (size - strip_w) // 2 + int(rng.integers(-size // 8, size // 8 + 1))
    start = int(np.clip(start, 0, size - strip_w))
    strip = small[:, start : start + strip_w]
    top = int(np.clip(n - size + rng.integers(-n // 10, n // 10 + 1), 0, n - size))
    out = patch.copy()
    if rng.random() < 0.5:
        out[top : top + size, :strip_w] = strip
    else:
        out[top : top + size, n - strip_w :] = strip
    return out


def low_resolution(image: np.ndarray, cone_px: float) -> np.ndarray:
    """The patch as a far cone `cone_px` tall gives it: area-down, bilinear up again (its shape
    kept; both sides scaled alike)."""
    height, width = image.shape[:2]
    scale = cone_px / PATCH_CONE_PX
    small_h, small_w = max(4, round(height * scale)), max(4, round(width * scale))
    if small_h >= height:
        return image
    down = cv2.resize(image, (small_w, small_h), interpolation=cv2.INTER_AREA)
    return cv2.resize(down, (width, height), interpolation=cv2.INTER_LINEAR)


# How tall a cone framed by the crop rule shows in the 80x80 patch (1/1.2 of the side, minus
# the labellers' margin), pixels.
PATCH_CONE_PX = 65.0


def photometric(image: np.ndarray, rng: np.random.Generator, p: AugmentParams) -> np.ndarray:
    if rng.random() < p.p_low_resolution:
        image = low_resolution(image, rng.uniform(*p.low_resolution_cone_px))
    x = image.astype(np.float32)
    if rng.random() < p.p_exposure:
        x = x * rng.uniform(*p.exposure_gain_range)
    if rng.random() < p.p_glare:
        x = x + rng.uniform(0.0, p.glare_max) * (1.0 - x / 255.0).clip(0.0, 1.0)
    if rng.random() < p.p_colour:
        gain = rng.uniform(*p.colour_gain_range, size=3).astype(np.float32)
        offset = rng.uniform(-p.colour_offset_max, p.colour_offset_max, size=3).astype(np.float32)
        x = x * gain + offset
    if rng.random() < p.p_gamma:
        x = 255.0 * (np.clip(x, 0, 255) / 255.0) ** rng.uniform(*p.gamma_range)
    if rng.random() < p.p_blur:
        if rng.random() < 0.7:
            x = cv2.GaussianBlur(x, (0, 0), rng.uniform(0.3, p.blur_sigma_max_px))
        else:
            length = int(rng.integers(2, p.motion_blur_max_px + 1))
            kernel = np.zeros((length, length), np.float32)
            kernel[length // 2, :] = 1.0 / length
            rot = cv2.getRotationMatrix2D(
                ((length - 1) / 2, (length - 1) / 2), rng.uniform(0, 180), 1.0
            )
            kernel = cv2.warpAffine(kernel, rot, (length, length))
            kernel /= max(float(kernel.sum()), 1e-6)
            x = cv2.filter2D(x, -1, kernel)
    if rng.random() < p.p_noise:
        x = x + rng.normal(0.0, rng.uniform(0.0, p.noise_sigma_max), size=x.shape)
    out = np.clip(x + 0.5, 0, 255).astype(np.uint8)
    if rng.random() < p.p_jpeg:
        quality = int(rng.integers(p.jpeg_quality_range[0], p.jpeg_quality_range[1] + 1))
        ok, encoded = cv2.imencode(".jpg", out[:, :, ::-1], [cv2.IMWRITE_JPEG_QUALITY, quality])
        if ok:
            out = np.ascontiguousarray(cv2.imdecode(encoded, cv2.IMREAD_COLOR)[:, :, ::-1])
    return out


class PhotoAugment:
    """The augmenter used in training: `augment(sample, rng) -> sample` (module docs)."""

    def __init__(
        self, params: AugmentParams | None = None, neighbours: PatchSource | None = None
    ) -> None:
        self.params = params or AugmentParams()
        self.neighbours = neighbours

    def __call__(self, sample: KeypointPatch, rng: np.random.Generator) -> KeypointPatch:
        p = self.params
        patch = np.asarray(sample.patch_rgb)
        keypoints = np.asarray(sample.keypoints_px, dtype=np.float64)
        if rng.random() < p.p_geometric:
            patch, keypoints = _geometric(patch, keypoints, rng, p)
        if rng.random() < p.p_mirror:
            patch, keypoints = _mirror(patch, keypoints)
        if self.neighbours is not None and len(self.neighbours) and rng.random() < p.p_neighbour:
            other = self.neighbours[int(rng.integers(len(self.neighbours)))].patch_rgb
            patch = _neighbour(patch, np.asarray(other), rng)
        if rng.random() < p.p_truncate:
            patch = _truncate(patch, rng, p)
        if rng.random() < p.p_occlude:
            patch = _occlude(patch, keypoints, rng, p)
        patch = photometric(patch, rng, p)
        return KeypointPatch(patch, keypoints.astype(np.float32))
