"""Copy-paste of real large orange cones (issue 38): the rarest class (462 of 19,151 real
training labels) and the weakest (AP 0.63 on the real test split, 0.35 on its degraded copy)
gets more, and more varied, examples by pasting real ones into training windows.

    python -m conesight_train.detector.paste \
        --data yolo:../shared/data/real-train/fsoco-boxes/train --out build/paste-large-orange.npz

The bank holds every large orange cone of the split at least MIN_HEIGHT_PX tall and not an
ignore region, cut with a margin of MARGIN of its box on each side (the road around it comes
along and is feathered into the window, so no hard rectangle edge gives the paste away).
`paste_cones` puts 1-2 of them into a window at a log-uniform height, where they overlap no
labelled box, and returns the window with their boxes added.
"""

from __future__ import annotations

import argparse
from functools import cache
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from conesight_train.detector.model import CLASS_NAMES

LARGE_ORANGE = CLASS_NAMES.index("large_orange")
MIN_HEIGHT_PX = 24.0
MARGIN = 0.15
PASTE_HEIGHT_PX = (10.0, 140.0)


def build_bank(data: str, class_index: int = LARGE_ORANGE) -> dict[str, np.ndarray]:
    """Patches of every cone of `class_index` in `data`, as one npz-ready dict."""
    from conesight_train.detector.config import open_source

    source = open_source(data)
    patches, boxes = [], []
    for i in tqdm(range(len(source)), desc="cutting cones"):
        frame = source[i]
        h, w = frame.image_rgb.shape[:2]
        hard = frame.difficult_mask()
        for box, cls, difficult in zip(frame.boxes_px, frame.classes, hard, strict=True):
            x0, y0, x1, y1 = (float(v) for v in box)
            if cls != class_index or difficult or y1 - y0 < MIN_HEIGHT_PX:
                continue
            mx, my = MARGIN * (x1 - x0), MARGIN * (y1 - y0)
            c0, r0 = int(np.floor(x0 - mx)), int(np.floor(y0 - my))
            c1, r1 = int(np.ceil(x1 + mx)), int(np.ceil(y1 + my))
            if c0 < 0 or r0 < 0 or c1 > w or r1 > h:
                continue  # cut by the frame's edge: not a whole cone
            patches.append(frame.image_rgb[r0:r1, c0:c1].copy())
            boxes.append([x0 - c0, y0 - r0, x1 - c0, y1 - r0])
    flat = np.concatenate([p.reshape(-1) for p in patches]) if patches else np.zeros(0, np.uint8)
    shapes = np.array([p.shape[:2] for p in patches], np.int64).reshape(-1, 2)
    return {"pixels": flat, "shapes": shapes, "boxes": np.array(boxes).reshape(-1, 4)}


@cache
def load_bank(path: str) -> tuple[list[np.ndarray], np.ndarray]:
    """(patches, boxes in patch px) of a bank file (read once per process)."""
    try:
        data = np.load(path)
    except (OSError, ValueError) as err:
        raise ValueError(
            f"{path}: cannot read the paste bank ({err}); cut it with "
            "`python -m conesight_train.detector.paste`"
        ) from err
    patches, offset = [], 0
    for h, w in data["shapes"]:
        n = int(h) * int(w) * 3
        patches.append(data["pixels"][offset : offset + n].reshape(int(h), int(w), 3))
        offset += n
    return patches, data["boxes"]


def _feather(h: int, w: int, box: np.ndarray) -> np.ndarray:
    """Alpha [h, w, 1]: 1 on the cone's box, falling to 0 at the patch's edge."""
    ys, xs = np.mgrid[0:h, 0:w].astype(np.float32) + 0.5
    dx = np.maximum(np.maximum(box[0] - xs, xs - box[2]), 0) / max(box[0], w - box[2], 1.0)
    dy = np.maximum(np.maximum(box[1] - ys, ys - box[3]), 0) / max(box[1], h - box[3], 1.0)
    return np.clip(1.0 - np.maximum(dx, dy), 0.0, 1.0)[..., None]


def paste_cones(
    canvas: np.ndarray,
    boxes: np.ndarray,
    bank: tuple[list[np.ndarray], np.ndarray],
    rng: np.random.Generator,
    count: int,
) -> tuple[np.ndarray, np.ndarray]:
    """`canvas` (HxWx3 uint8) with up to `count` bank cones pasted where they overlap none of
    `boxes`; returns the canvas and the pasted boxes [N, 4] (canvas px)."""
    patches, patch_boxes = bank
    out = canvas.copy()
    placed: list[list[float]] = []
    ch, cw = canvas.shape[:2]
    taken = [*boxes.reshape(-1, 4).tolist()]
    for _ in range(count):
        k = int(rng.integers(len(patches)))
        patch, box = patches[k], patch_boxes[k]
        lo, hi = np.log(PASTE_HEIGHT_PX[0]), np.log(min(PASTE_HEIGHT_PX[1], 0.8 * ch))
        scale = float(np.exp(rng.uniform(lo, hi))) / (box[3] - box[1])
        ph, pw = max(2, round(patch.shape[0] * scale)), max(2, round(patch.shape[1] * scale))
        if ph >= ch or pw >= cw:
            continue
        interpolation = cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR
        resized = cv2.resize(patch, (pw, ph), interpolation=interpolation)
        if rng.random() < 0.5:
            resized = resized[:, ::-1]
            box = np.array([patch.shape[1] - box[2], box[1], patch.shape[1] - box[0], box[3]])
        sx, sy = pw / patch.shape[1], ph / patch.shape[0]
        b = np.asarray(box, np.float64) * [sx, sy, sx, sy]
        x, y = int(rng.integers(0, cw - pw + 1)), int(rng.integers(0, ch - ph + 1))
        new = [x + b[0], y + b[1], x + b[2], y + b[3]]
        if any(
            min(new[2], t[2]) > max(new[0], t[0]) and min(new[3], t[3]) > max(new[1], t[1])
            for t in taken
        ):
            continue
        alpha = _feather(ph, pw, b)
        region = out[y : y + ph, x : x + pw].astype(np.float32)
        out[y : y + ph, x : x + pw] = (alpha * resized + (1 - alpha) * region).astype(np.uint8)
        placed.append(new)
        taken.append(new)
    return out, np.array(placed, np.float64).reshape(-1, 4)


def main(argv: list[str] | None = None) -> None:
    """CLI: cut the bank of a split's large orange cones."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--data", required=True)
    parser.add_argument("--out", required=True, type=Path)
    args = parser.parse_args(argv)
    bank = build_bank(args.data)
    args.out.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(args.out, **bank)
    print(f"{len(bank['shapes'])} large orange cones -> {args.out}")


if __name__ == "__main__":
    main()
