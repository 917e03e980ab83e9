"""Crop-rule parity: re-cuts the renderer's patches from its frames with `crop.py` and compares.

The renderer (Rust, `conesight_vision::crop_patch`) writes `images/NNNNNN.png` and, per patch,
`patches/NNNNNN_CCC.png` with `frame_index`, `box_px` and `transform` in
`patches/index.jsonl`. The Python mirror must give the same transform (to float rounding) and
the same pixels (exactly, for PNG frames). Used by the tests and by `python -m
conesight_train.parity ROOT`.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from conesight_train.crop import CropParams, PatchTransform, PixelBox, crop_patch
from conesight_train.data.errors import LabelError
from conesight_train.data.patches import read_rgb
from conesight_train.data.sim_patches import read_patch_index


@dataclass(frozen=True)
class ParityReport:
    """How far the Python crop is from the renderer's patches."""

    patches: int
    max_pixel_diff: int
    differing_pixels: int
    max_transform_diff: float


def patch_parity(root: str | Path, limit: int | None = None) -> ParityReport:
    """Compares up to `limit` patches of a rendered data set; raises LabelError on bad lines."""
    root = Path(root)
    records = read_patch_index(root)[:limit]
    frames: dict[int, np.ndarray] = {}
    max_diff, differing, max_transform = 0, 0, 0.0
    for record in records:
        extra = record.extra
        try:
            frame_index = int(extra["frame_index"])
            x_min, y_min, x_max, y_max = (float(v) for v in extra["box_px"])
            written = extra["transform"]
        except (KeyError, TypeError, ValueError) as err:
            raise LabelError(
                root / "patches" / "index.jsonl",
                f"needs frame_index, box_px, transform: {err!r}",
                record.line,
            ) from err
        if frame_index not in frames:
            frames = {frame_index: read_rgb(root / "images" / f"{frame_index:06}.png")}
        patch_rgb = read_rgb(record.image_path)
        params = CropParams(patch_size_px=patch_rgb.shape[0])
        ours, transform = crop_patch(
            frames[frame_index], PixelBox(x_min, y_min, x_max, y_max), params
        )
        expected = PatchTransform(
            float(written["x0_px"]),
            float(written["y0_px"]),
            float(written["scale"]),
            int(written["patch_size_px"]),
        )
        max_transform = max(
            max_transform,
            abs(transform.x0_px - expected.x0_px),
            abs(transform.y0_px - expected.y0_px),
            abs(transform.scale - expected.scale),
        )
        diff = np.abs(ours.astype(int) - patch_rgb.astype(int))
        max_diff = max(max_diff, int(diff.max()))
        differing += int((diff > 0).sum())
    return ParityReport(len(records), max_diff, differing, max_transform)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("root", type=Path, help="renderer output folder (json/png + patches)")
    parser.add_argument("--limit", type=int)
    args = parser.parse_args(argv)
    print(patch_parity(args.root, args.limit))


if __name__ == "__main__":
    main()
