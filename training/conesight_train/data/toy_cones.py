"""Procedural cone patches with exact keypoints, for tests and smoke runs (not for shipped
models: those train on the renderer's output).

A cone is a trapezoid (base half-width, top half-width, height) with one contrasting stripe
between the heights of the lower and upper stripe edges of the small cone (112.8 and 212.2 mm of
325 mm, so the side cross-ratio is Cr3D), rotated by a small lean, on a noisy background; drawn
at 4x and area-averaged for anti-aliasing. Keypoints: apex = top centre; side keypoints on the
silhouette edges at the stripe-edge heights and at the base.
"""

from __future__ import annotations

import cv2
import numpy as np

from conesight_train.data.patches import InMemoryPatches

# Keypoint heights as fractions of the cone height: base, lower, upper stripe edge, apex.
LEVEL_FRACTIONS = (0.0, 112.8 / 325.0, 212.2 / 325.0, 1.0)
BODY_COLOURS = ((30, 60, 200), (230, 200, 30), (240, 110, 20))
STRIPE_COLOURS = ((240, 240, 240), (20, 20, 20), (240, 240, 240))
SUPERSAMPLE = 4


def _draw_cone(rng: np.random.Generator, size_px: int) -> tuple[np.ndarray, np.ndarray]:
    big = size_px * SUPERSAMPLE
    background = rng.integers(60, 200, size=3)
    canvas = np.empty((big, big, 3), dtype=np.float32)
    canvas[:] = background
    height = rng.uniform(0.55, 0.8) * size_px
    base_half = height * rng.uniform(0.30, 0.40)
    top_half = base_half * rng.uniform(0.2, 0.35)
    cx = size_px / 2 + rng.uniform(-0.08, 0.08) * size_px
    base_y = size_px / 2 + height / 2 + rng.uniform(-0.05, 0.05) * size_px
    lean = rng.uniform(-0.12, 0.12)  # radians
    rot = np.array([[np.cos(lean), -np.sin(lean)], [np.sin(lean), np.cos(lean)]])

    def at(side: float, level: float) -> np.ndarray:
        half = base_half + (top_half - base_half) * level
        local = np.array([side * half, -level * height])
        return np.array([cx, base_y]) + rot @ local

    colour = int(rng.integers(len(BODY_COLOURS)))
    body = np.array([at(-1, 0), at(-1, 1), at(1, 1), at(1, 0)])
    lo, up = LEVEL_FRACTIONS[1], LEVEL_FRACTIONS[2]
    stripe = np.array([at(-1, lo), at(-1, up), at(1, up), at(1, lo)])

    def fill(poly: np.ndarray, rgb: tuple[int, int, int]) -> None:
        scaled = ((poly + 0.5) * SUPERSAMPLE - 0.5) * 16  # 4 fractional bits
        cv2.fillPoly(canvas, [np.round(scaled).astype(np.int32)], rgb, cv2.LINE_AA, shift=4)

    fill(body, BODY_COLOURS[colour])
    fill(stripe, STRIPE_COLOURS[colour])
    image = cv2.resize(canvas, (size_px, size_px), interpolation=cv2.INTER_AREA)
    image += rng.normal(0.0, rng.uniform(1.0, 6.0), size=image.shape)
    apex = np.array([cx, base_y]) + rot @ np.array([0.0, -height])
    keypoints = np.array(
        [apex, at(-1, up), at(-1, lo), at(-1, 0), at(1, up), at(1, lo), at(1, 0)],
        dtype=np.float32,
    )
    return np.clip(image, 0, 255).astype(np.uint8), keypoints


def toy_cone_patches(count: int, seed: int, size_px: int = 80) -> InMemoryPatches:
    """`count` procedural cone patches, reproducible from `seed`."""
    rng = np.random.default_rng(seed)
    patches = np.empty((count, size_px, size_px, 3), dtype=np.uint8)
    keypoints = np.empty((count, 7, 2), dtype=np.float32)
    for i in range(count):
        patches[i], keypoints[i] = _draw_cone(rng, size_px)
    return InMemoryPatches(patches, keypoints)
