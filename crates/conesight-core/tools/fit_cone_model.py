#!/usr/bin/env python3
"""Fit the small cone's body radii (conesight-core `cone/model.rs`) to real keypoint labels.

Usage: python3 fit_cone_model.py [CROPS_DIR]   (needs numpy; CROPS_DIR defaults to
../../../../shared/data/real-dev/fsoco-keypoint-crops relative to this file)

1. Real label statistics. For every crop with exactly 7 labelled points (Supervisely array order
   base_R, lower_R, upper_R, apex, upper_L, lower_L, base_L; conesight order = indices
   [3, 4, 5, 6, 2, 1, 0]), the apex-to-base image height is the distance from the apex to the
   midpoint of the two base points; crops with a height below 40 px are dropped. The statistic
   per level is the median over crops of (distance between the left and right points) / height.
2. Model. The keypoint heights are fixed by the paper (0, 112.8, 212.2, 325 mm, Cr3D = 1.39408).
   The body is a straight-tapered truncated cone with radius r_base at h = 0 and r_top at the
   top (two parameters). Its image keypoints are the exact silhouette points (the same closed
   form as `cone/silhouette.rs`) for the typical view: pinhole camera 1.0 m above the ground,
   looking level, cone 8 m straight ahead. Perspective makes the image ratios differ from the
   3D ratios by about 1 %, which is why the fit projects instead of dividing 3D lengths.
3. Fit. Gauss-Newton least squares of the three projected ratios against the three medians.
   The printed constants go into `SMALL_BASE_RADIUS_M` and `SMALL_TOP_RADIUS_M`.
"""

from __future__ import annotations

import glob
import json
import os
import sys

import numpy as np

HEIGHTS_M = np.array([0.0, 0.1128, 0.2122, 0.325])
MIN_HEIGHT_PX = 40.0
CAMERA_HEIGHT_M = 1.0
TYPICAL_DISTANCE_M = 8.0
FOCAL_PX = 2047.8


def real_ratios(crops_dir: str) -> tuple[np.ndarray, int, np.ndarray]:
    """Median (base, lower, upper) width / height over the real labels, count, all ratios."""
    rows = []
    for path in sorted(glob.glob(os.path.join(crops_dir, "ann", "*.json"))):
        with open(path) as f:
            objects = json.load(f)["objects"]
        if len(objects) != 7:
            continue
        points = np.array([o["points"]["exterior"][0] for o in objects], dtype=float)
        rows.append(points[[3, 4, 5, 6, 2, 1, 0]])
    keypoints = np.array(rows)
    apex, left, right = keypoints[:, 0], keypoints[:, 1:4], keypoints[:, 4:7]
    height = np.linalg.norm(apex - (left[:, 2] + right[:, 2]) / 2, axis=1)
    keep = height >= MIN_HEIGHT_PX
    # columns: base, lower, upper
    widths = np.linalg.norm(left[:, ::-1] - right[:, ::-1], axis=2) / height[:, None]
    return np.median(widths[keep], axis=0), int(keep.sum()), widths[keep]


def silhouette_pixels(r_base: float, r_top: float, distance_m: float, lateral_m: float = 0.0):
    """Apex and (left, right) silhouette pixels at the base, lower and upper stripe heights."""
    slope = (r_top - r_base) / HEIGHTS_M[3]
    radii = r_base + slope * HEIGHTS_M
    # Cone frame: camera at c; the cone axis at the origin.
    c = np.array([-distance_m, -lateral_m, CAMERA_HEIGHT_M])
    rho = np.hypot(c[0], c[1])
    r_cam = r_base + slope * c[2]
    phi = np.arctan2(c[1], c[0])
    alpha = np.arccos(r_cam / rho)

    def project(p):
        # Camera looks along +x (cone frame = vehicle frame here), OpenCV axes.
        d = p - c
        return np.array([FOCAL_PX * -d[1] / d[0], FOCAL_PX * -d[2] / d[0]])

    apex = project(np.array([0.0, 0.0, HEIGHTS_M[3]]))
    sides = []
    for theta in (phi - alpha, phi + alpha):
        sides.append(
            [project(np.array([r * np.cos(theta), r * np.sin(theta), h]))
             for r, h in zip(radii[:3], HEIGHTS_M[:3])]
        )
    return apex, np.array(sides)  # sides[side, level(base, lower, upper)]


def model_ratios(r_base: float, r_top: float, distance_m: float, lateral_m: float = 0.0):
    """Projected (base, lower, upper) width / apex-to-base height."""
    apex, sides = silhouette_pixels(r_base, r_top, distance_m, lateral_m)
    height = np.linalg.norm(apex - (sides[0, 0] + sides[1, 0]) / 2)
    return np.linalg.norm(sides[0] - sides[1], axis=1) / height


def fit(target: np.ndarray) -> np.ndarray:
    """Gauss-Newton fit of (r_base, r_top) to the target ratios at the typical view."""
    params = np.array([0.075, 0.02])
    for _ in range(20):
        residual = model_ratios(*params, TYPICAL_DISTANCE_M) - target
        jacobian = np.empty((3, 2))
        for j in range(2):
            step = np.zeros(2)
            step[j] = 1e-7
            jacobian[:, j] = (model_ratios(*(params + step), TYPICAL_DISTANCE_M)
                              - model_ratios(*(params - step), TYPICAL_DISTANCE_M)) / 2e-7
        params = params - np.linalg.lstsq(jacobian, residual, rcond=None)[0]
    return params


def main() -> None:
    here = os.path.dirname(os.path.abspath(__file__))
    default = os.path.join(here, "..", "..", "..", "..", "shared", "data", "real-dev",
                           "fsoco-keypoint-crops")
    crops_dir = sys.argv[1] if len(sys.argv) > 1 else default
    target, count, all_ratios = real_ratios(crops_dir)
    q25, q75 = np.percentile(all_ratios, [25, 75], axis=0)
    print(f"real labels: {count} crops with height >= {MIN_HEIGHT_PX} px")
    for i, name in enumerate(["base", "lower", "upper"]):
        print(f"  {name:5s} width/height median {target[i]:.4f} (IQR {q25[i]:.3f}-{q75[i]:.3f})")
    r_base, r_top = fit(target)
    radii = r_base + (r_top - r_base) / HEIGHTS_M[3] * HEIGHTS_M
    print(f"fitted: r_base = {r_base:.4f} m, r_top = {r_top:.4f} m; keypoint radii "
          + ", ".join(f"{r:.4f}" for r in radii))
    print(f"  3D ratios (2 r / 0.325 m): {np.round(2 * radii[:3] / HEIGHTS_M[3], 4)}")
    for distance in [3.0, 5.0, 8.0, 12.0, 15.0]:
        for lateral in [0.0, 2.0]:
            ratios = model_ratios(r_base, r_top, distance, lateral)
            error = 100 * (ratios / target - 1)
            print(f"  view {distance:4.1f} m ahead, {lateral:.0f} m aside: ratios "
                  f"{np.round(ratios, 4)}  vs real {np.round(error, 1)} %")
    print(f"\nconst SMALL_BASE_RADIUS_M: f64 = {r_base:.4f};")
    print(f"const SMALL_TOP_RADIUS_M: f64 = {r_top:.4f};")


if __name__ == "__main__":
    main()
