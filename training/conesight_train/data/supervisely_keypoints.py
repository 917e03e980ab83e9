"""Reader for Supervisely keypoint crops (e.g. `../shared/data/real-dev/fsoco-keypoint-crops`).

Layout: `img/NAME.png` and `ann/NAME.png.json`. Each annotation holds `size` and 7 point
objects whose `points.exterior[0]` is `[x, y]` in crop pixels; the ORDER of the objects is the
keypoint identity:

    0 base right, 1 lower right, 2 upper right, 3 apex, 4 upper left, 5 lower left, 6 base left

so conesight's order (apex; left upper, lower, base; right upper, lower, base) is array indices
`SUPERVISELY_TO_CONESIGHT = [3, 4, 5, 6, 2, 1, 0]`. Files whose point count is not 7 are skipped
and counted (the data set has a few); anything else malformed raises `LabelError`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from conesight_train.data.errors import LabelError
from conesight_train.keypoints import KEYPOINT_COUNT

SUPERVISELY_TO_CONESIGHT: tuple[int, ...] = (3, 4, 5, 6, 2, 1, 0)


@dataclass(frozen=True)
class KeypointCrop:
    """One labelled crop: the image file, its size and 7 keypoints (x, y) in crop pixels."""

    image_path: Path
    width_px: int
    height_px: int
    keypoints_px: np.ndarray  # (7, 2) float64, conesight order
    tags: tuple[str, ...]


@dataclass
class KeypointCropSet:
    """The readable crops of a folder and the files skipped for not having 7 points."""

    crops: list[KeypointCrop]
    skipped_point_count: list[Path] = field(default_factory=list)


def _parse_annotation(ann_path: Path) -> tuple[int, int, np.ndarray | None, tuple[str, ...]]:
    try:
        data = json.loads(ann_path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        raise LabelError(ann_path, f"not valid JSON: {err.msg}", line=err.lineno) from err
    try:
        width = int(data["size"]["width"])
        height = int(data["size"]["height"])
        objects = data["objects"]
        tags = tuple(str(tag["name"]) for tag in data.get("tags", []))
    except (KeyError, TypeError, ValueError) as err:
        raise LabelError(
            ann_path, f"missing or malformed 'size'/'objects'/'tags': {err!r}"
        ) from err
    if len(objects) != KEYPOINT_COUNT:
        return width, height, None, tags
    points = []
    for index, obj in enumerate(objects):
        try:
            exterior = obj["points"]["exterior"]
            x, y = (float(v) for v in exterior[0])
        except (KeyError, TypeError, ValueError, IndexError) as err:
            raise LabelError(
                ann_path, f"object {index}: expected points.exterior[0] = [x, y] ({err!r})"
            ) from err
        if not (np.isfinite(x) and np.isfinite(y)):
            raise LabelError(ann_path, f"object {index}: point ({x}, {y}) is not finite")
        points.append((x, y))
    keypoints = np.asarray(points, dtype=np.float64)[list(SUPERVISELY_TO_CONESIGHT)]
    return width, height, keypoints, tags


def read_keypoint_crops(root: str | Path) -> KeypointCropSet:
    """Reads every `ann/*.json` under `root` whose image `img/NAME` exists, sorted by name."""
    root = Path(root)
    ann_dir, img_dir = root / "ann", root / "img"
    if not ann_dir.is_dir() or not img_dir.is_dir():
        raise LabelError(root, "expected the Supervisely layout with 'ann/' and 'img/' folders")
    result = KeypointCropSet(crops=[])
    for ann_path in sorted(ann_dir.glob("*.json")):
        image_path = img_dir / ann_path.name.removesuffix(".json")
        if not image_path.is_file():
            raise LabelError(ann_path, f"its image {image_path} does not exist")
        width, height, keypoints, tags = _parse_annotation(ann_path)
        if keypoints is None:
            result.skipped_point_count.append(ann_path)
            continue
        result.crops.append(KeypointCrop(image_path, width, height, keypoints, tags))
    return result
