"""Real keypoint crops as training and validation sources, split by source frame.

Two layouts are read as they come:

- Supervisely (`ann/NAME.png.json` + `img/NAME.png`, e.g. `real-dev/fsoco-keypoint-crops`),
  crop names `amz_<frame>_<n>.png`;
- a `keypoints.json` list of `{"image", "width_px", "height_px", "keypoints_px"}` in conesight's
  order (e.g. `real-train/amz-keypoint-crops-hires`), crop names
  `amz_<frame>_<x1>_<y1>_<x2>_<y2>.jpg`.

The split is by source frame, so no frame gives crops to two parts. With `c` the CRC-32 of the
frame id modulo 100: validation `c < 15` (model choice and every reported real number),
calibration `15 <= c < 25` (fits the one scale factor of the exported sigma, nothing else),
training the rest. The split is a pure function of the file names; it does not depend on the
order, the count or a seed.

Data spec (`--train` / `--val` and `make eval`): `real:DIR[:train|val|calib|all][*REPEAT]`, e.g.
`real:../shared/data/real-dev/fsoco-keypoint-crops:train*4` (the training part, four times per
epoch, each time with its own augmentation).
"""

from __future__ import annotations

import json
import re
import zlib
from pathlib import Path

import numpy as np

from conesight_train.data.errors import LabelError
from conesight_train.data.supervisely_keypoints import KeypointCrop, read_keypoint_crops
from conesight_train.keypoints import KEYPOINT_COUNT

VAL_PERCENT = 15
CALIB_PERCENT = 10
SPLITS = ("train", "val", "calib", "all")
_FRAME = re.compile(r"^([A-Za-z]+_\d+)_")


def source_frame(path: Path) -> str:
    """The source frame id of a crop file (`amz_00534` of `amz_00534_1746_...jpg`)."""
    match = _FRAME.match(path.name)
    if match is None:
        raise LabelError(path, "crop name does not start with <team>_<frame>_; cannot split")
    return match.group(1)


def frame_split(frame: str) -> str:
    """ "val", "calib" or "train" for a source frame id (module docs)."""
    bucket = zlib.crc32(frame.encode("utf-8")) % 100
    if bucket < VAL_PERCENT:
        return "val"
    if bucket < VAL_PERCENT + CALIB_PERCENT:
        return "calib"
    return "train"


def read_keypoints_json(root: str | Path) -> list[KeypointCrop]:
    """The crops of `root/keypoints.json` (module docs), with their images checked to exist."""
    root = Path(root)
    index = root / "keypoints.json"
    try:
        entries = json.loads(index.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        raise LabelError(index, f"not valid JSON: {err.msg}", line=err.lineno) from err
    if not isinstance(entries, list):
        raise LabelError(index, "expected a list of crops")
    crops = []
    for number, entry in enumerate(entries):
        try:
            image = root / str(entry["image"])
            width, height = int(entry["width_px"]), int(entry["height_px"])
            keypoints = np.asarray(entry["keypoints_px"], dtype=np.float64)
        except (KeyError, TypeError, ValueError) as err:
            raise LabelError(index, f"crop {number}: missing or malformed field ({err!r})") from err
        if keypoints.shape != (KEYPOINT_COUNT, 2) or not np.isfinite(keypoints).all():
            raise LabelError(index, f"crop {number}: keypoints_px must be 7 finite [x, y]")
        if not image.is_file():
            raise LabelError(index, f"crop {number}: its image {image} does not exist")
        crops.append(KeypointCrop(image, width, height, keypoints, ()))
    return crops


def read_real_crops(root: str | Path) -> list[KeypointCrop]:
    """Every usable crop of a folder in either layout (module docs)."""
    root = Path(root)
    if (root / "keypoints.json").is_file():
        return read_keypoints_json(root)
    if (root / "ann").is_dir():
        return read_keypoint_crops(root).crops
    raise LabelError(root, "expected keypoints.json or the Supervisely ann/ + img/ folders")


def split_crops(crops: list[KeypointCrop], split: str) -> list[KeypointCrop]:
    """The crops of `split` ("train", "val", "calib" or "all"), by source frame."""
    if split not in SPLITS:
        raise ValueError(f"unknown split {split!r}; expected one of {SPLITS}")
    if split == "all":
        return list(crops)
    return [c for c in crops if frame_split(source_frame(c.image_path)) == split]


def parse_real_spec(spec: str) -> tuple[Path, str, int]:
    """`real:DIR[:SPLIT][*REPEAT]` -> (DIR, SPLIT, REPEAT); SPLIT defaults to "all"."""
    body = spec.removeprefix("real:")
    repeat = 1
    if "*" in body:
        body, _, count = body.rpartition("*")
        try:
            repeat = int(count)
        except ValueError as err:
            raise ValueError(f"bad repeat in {spec!r}; expected real:DIR[:SPLIT][*N]") from err
        if repeat < 1:
            raise ValueError(f"repeat must be >= 1 in {spec!r}")
    split = "all"
    head, sep, tail = body.rpartition(":")
    if sep and tail in SPLITS:
        body, split = head, tail
    if not body:
        raise ValueError(f"no folder in {spec!r}; expected real:DIR[:SPLIT][*N]")
    return Path(body), split, repeat
