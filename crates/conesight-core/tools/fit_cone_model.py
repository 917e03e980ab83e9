#!/usr/bin/env python3
"""Fit the small cone's keypoint heights and body radii (conesight-core `cone/model.rs`) to real
cones: the keypoints the network puts on labelled FSOCO boxes.

Usage: python3 fit_cone_model.py RECORDS   (needs numpy; RECORDS is `real_cones.jsonl` from
`conesight-eval --real-boxes ../shared/data/real-train/fsoco-boxes`, as `make eval` writes it
into build/eval)

1. Cones. The `labelled` records of the training split: fully visible (not cut by the photo's
   edge, overlapping no other box), small classes, box at least 40 px tall (smaller boxes give
   too few pixels per keypoint).
2. Metres. A cone's box spans its full height H = 325 mm (FSG: 228 x 228 x 325 mm), from the
   base plate's front edge on the road to the top of the body. For a level camera c = 1 m above
   the road, the plate's front edge is p = 4/pi x 114 mm (its mean over yaw) nearer than the
   axis and shows e = c p / (d - p) metres lower than the base centre would, so the box is
   (H + e) f / d tall: s = (H + e) / box_height metres per pixel at the cone, with d solved
   from d = f (H + e) / box_height (f: the record's assumed focal length; e is small, so f's
   error hardly matters). A keypoint `y` pixels above the box's bottom is at height `y s - e`;
   a left-right distance `w` is a radius of `w s / 2`.
3. Fit. The median height of each level (base, lower and upper stripe edge, apex) and the
   median radius at the base and the two stripe edges; a straight taper is fitted through the
   three radii by least squares. The printed constants go into `model.rs`.
4. Scale. The PnP solver uses every keypoint at once, with the silhouette's exact geometry, so
   the medians of step 3 need not give ranges that agree with the boxes'. The records carry
   both ranges for the geometry they were made with: the median of keypoints / box over the
   training split's visible cones (small ones at least 20 px tall, large ones at least 10 px)
   is the factor by which that geometry's keypoint heights and radii are too large. It goes
   into `SMALL_KEYPOINT_SCALE` and `LARGE_KEYPOINT_SCALE` (times the ones in use).
"""

from __future__ import annotations

import json
import sys

import numpy as np

BODY_HEIGHT_M = 0.325
PLATE_M = 0.114 * 4.0 / np.pi
CAMERA_HEIGHT_M = 1.0
MIN_BOX_PX = 40.0


def cones(path: str) -> list[dict]:
    rows = []
    with open(path, encoding="utf-8") as f:
        for line in f:
            r = json.loads(line)
            if (
                r["boxes"] == "labelled"
                and r["split"] == "train"
                and r["visible"]
                and r["class"] != "large_orange"
                and r["box_height_px"] >= MIN_BOX_PX
                and r["keypoints_px"] is not None
            ):
                rows.append(r)
    return rows


def in_metres(r: dict) -> tuple[np.ndarray, np.ndarray]:
    """Heights of (base, lower, upper, apex) and radii at (base, lower, upper), metres."""
    k = np.asarray(r["keypoints_px"])
    b = r["box_px"]
    box_h = b[3] - b[1]
    d = r["f_px"] * BODY_HEIGHT_M / box_h
    for _ in range(8):
        e = CAMERA_HEIGHT_M * PLATE_M / (d - PLATE_M)
        d = r["f_px"] * (BODY_HEIGHT_M + e) / box_h
    s = (BODY_HEIGHT_M + e) / box_h
    mid = [(k[3] + k[6]) / 2, (k[2] + k[5]) / 2, (k[1] + k[4]) / 2, k[0]]
    heights = np.array([(b[3] - p[1]) * s - e for p in mid])
    radii = np.array(
        [np.linalg.norm(k[left] - k[right]) * s / 2 for left, right in [(3, 6), (2, 5), (1, 4)]]
    )
    return heights, radii


def scale_steps(path: str) -> dict[str, tuple[int, float]]:
    """Median keypoint/box range ratio and count, per size (module docs, step 4)."""
    ratios: dict[str, list[float]] = {"small": [], "large": []}
    with open(path, encoding="utf-8") as f:
        for line in f:
            r = json.loads(line)
            size = "large" if r["class"] == "large_orange" else "small"
            if (
                r["boxes"] == "labelled"
                and r["split"] == "train"
                and r["visible"]
                and r["range_keypoints_m"]
                and r["range_box_m"]
                and r["box_height_px"] >= (10.0 if size == "large" else 20.0)
            ):
                ratios[size].append(r["range_keypoints_m"] / r["range_box_m"])
    return {k: (len(v), float(np.median(v))) for k, v in ratios.items() if v}


def main() -> None:
    if len(sys.argv) != 2:
        sys.exit(__doc__)
    rows = cones(sys.argv[1])
    h, r = zip(*(in_metres(x) for x in rows), strict=True)
    heights = np.median(np.array(h), axis=0)
    radii = np.median(np.array(r), axis=0)
    slope, intercept = np.polyfit(heights[:3], radii, 1)
    print(f"{len(rows)} cones (train split, visible, >= {MIN_BOX_PX:.0f} px)")
    print("keypoint heights (base, lower, upper, apex), m:", np.round(heights, 4))
    print("radii at base, lower, upper, m:", np.round(radii, 4))
    base, apex = (intercept + slope * heights[i] for i in (0, 3))
    print(
        f"straight taper: {slope:.4f} m/m; radius {base:.4f} m at the base keypoint, "
        f"{apex:.4f} m at the apex height"
    )
    for size, (count, ratio) in scale_steps(sys.argv[1]).items():
        print(
            f"{size}: median keypoint / box range {ratio:.4f} over {count} cones: scale the "
            f"keypoint geometry in use by {1.0 / ratio:.4f}"
        )


if __name__ == "__main__":
    main()
