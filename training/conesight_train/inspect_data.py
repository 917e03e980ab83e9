"""Reads a keypoint data set, checks it and draws it (`conesight-inspect-data`).

Sources: `--sim DIR` (renderer patches), `--real-crops DIR` (Supervisely keypoint crops),
`--rektnet CSV --images DIR` (RektNet crops), `--toy COUNT`. Every crop-type source is cut by the
crop rule into 80x80 patches first, so what is drawn is what the network sees.

Prints the sample count, the files skipped, how many keypoints fall outside the patch and the
median cross-ratio of each side (the labels' order is right when it is near Cr3D = 1.394), and
writes `--out` (PNG): a grid of patches with the keypoints drawn (apex white, image-left side
green, image-right side magenta; darker = lower).
"""

from __future__ import annotations

import argparse
from pathlib import Path

import cv2
import numpy as np
import torch

from conesight_train.data.patches import PatchSource, RealCropPatches, read_rgb
from conesight_train.data.rektnet_csv import read_rektnet_csv
from conesight_train.data.sim_patches import SimPatches
from conesight_train.data.supervisely_keypoints import KeypointCrop, read_keypoint_crops
from conesight_train.data.toy_cones import toy_cone_patches
from conesight_train.keypoints import CR3D
from conesight_train.losses import cross_ratio, cross_ratio_penalty

# BGR colours per keypoint for drawing.
KEYPOINT_COLOURS_BGR: tuple[tuple[int, int, int], ...] = (
    (255, 255, 255),
    (80, 255, 80),
    (40, 190, 40),
    (20, 120, 20),
    (255, 80, 255),
    (190, 40, 190),
    (120, 20, 120),
)
DRAW_SCALE = 3


def rektnet_crops(csv_path: Path, image_dir: Path) -> list[KeypointCrop]:
    """RektNet rows as crops (the image is the crop; its size read from the file)."""
    crops = []
    for row in read_rektnet_csv(csv_path):
        path = image_dir / row.image
        height, width = read_rgb(path).shape[:2]
        crops.append(KeypointCrop(path, width, height, row.keypoints_px, ()))
    return crops


def _to_draw(x: float, y: float) -> tuple[int, int]:
    return round(float(x + 0.5) * DRAW_SCALE - 0.5), round(float(y + 0.5) * DRAW_SCALE - 0.5)


def draw_grid(
    source: PatchSource,
    count: int,
    columns: int = 10,
    predicted_px: np.ndarray | None = None,
) -> np.ndarray:
    """BGR image: the first `count` patches, upscaled, labels as dots; with `predicted_px`
    [count, 7, 2], predictions as crosses of the same colour."""
    tiles = []
    for index in range(min(count, len(source))):
        sample = source[index]
        tile = cv2.resize(
            np.ascontiguousarray(sample.patch_rgb[:, :, ::-1]),
            None,
            fx=DRAW_SCALE,
            fy=DRAW_SCALE,
            interpolation=cv2.INTER_NEAREST,
        )
        for k, (x, y) in enumerate(np.asarray(sample.keypoints_px)):
            cv2.circle(tile, _to_draw(x, y), 3, KEYPOINT_COLOURS_BGR[k], -1, cv2.LINE_AA)
        if predicted_px is not None:
            for k, (x, y) in enumerate(predicted_px[index]):
                colour = KEYPOINT_COLOURS_BGR[k]
                cv2.drawMarker(tile, _to_draw(x, y), colour, cv2.MARKER_CROSS, 9, 1, cv2.LINE_AA)
        tiles.append(tile)
    if not tiles:
        raise ValueError("the data set is empty")
    blank = np.zeros_like(tiles[0])
    while len(tiles) % columns:
        tiles.append(blank)
    rows = [np.hstack(tiles[i : i + columns]) for i in range(0, len(tiles), columns)]
    return np.vstack(rows)


def statistics(source: PatchSource, limit: int) -> dict[str, float]:
    """Keypoints outside the patch and the median cross-ratio per side over `limit` samples."""
    keypoints = np.stack(
        [np.asarray(source[i].keypoints_px) for i in range(min(limit, len(source)))]
    )
    size = source[0].patch_rgb.shape[0]
    outside = (keypoints < -0.5) | (keypoints > size - 0.5)
    k = torch.from_numpy(keypoints.astype(np.float64))
    left = cross_ratio(k[:, 0], k[:, 1], k[:, 2], k[:, 3]).numpy()
    right = cross_ratio(k[:, 0], k[:, 4], k[:, 5], k[:, 6]).numpy()
    return {
        "samples_checked": float(len(keypoints)),
        "keypoints_outside_patch": float(outside.any(axis=-1).sum()),
        "median_cross_ratio_left": float(np.median(left)),
        "median_cross_ratio_right": float(np.median(right)),
        "median_cross_ratio_penalty": float(np.median(cross_ratio_penalty(k).numpy())),
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    group = parser.add_mutually_exclusive_group(required=True)
    group.add_argument("--sim", type=Path, help="renderer output folder")
    group.add_argument("--real-crops", type=Path, help="Supervisely keypoint crop folder")
    group.add_argument("--rektnet", type=Path, help="RektNet CSV (with --images)")
    group.add_argument("--toy", type=int, help="procedural cones")
    parser.add_argument("--images", type=Path, help="image folder of the RektNet CSV")
    parser.add_argument(
        "--real-outside", choices=RealCropPatches.OUTSIDE_MODES, default="replicate"
    )
    parser.add_argument("--out", type=Path, default=Path("build/inspect.png"))
    parser.add_argument("--count", type=int, default=60, help="patches drawn")
    parser.add_argument("--check", type=int, default=5000, help="patches checked")
    args = parser.parse_args(argv)

    source: PatchSource
    if args.sim:
        source = SimPatches(args.sim)
    elif args.real_crops:
        crop_set = read_keypoint_crops(args.real_crops)
        print(f"skipped (not 7 points): {len(crop_set.skipped_point_count)}")
        source = RealCropPatches(crop_set.crops, outside=args.real_outside)
    elif args.rektnet:
        if args.images is None:
            parser.error("--rektnet needs --images DIR")
        source = RealCropPatches(
            rektnet_crops(args.rektnet, args.images), outside=args.real_outside
        )
    else:
        source = toy_cone_patches(args.toy, seed=0)
    print(f"samples: {len(source)}")
    for key, value in statistics(source, args.check).items():
        print(f"{key}: {value:.4g}")
    print(f"(Cr3D = {CR3D})")
    args.out.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(args.out), draw_grid(source, args.count))
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
