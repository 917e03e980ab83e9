"""Real labelled frames as they come, as `LabelledFrame`s: YOLO folders (Roboflow/Ultralytics
exports, e.g. `../shared/data/real-train/fsoco-boxes/{train,valid,test}`) and FSOCO's own
Supervisely layout (`TEAM/img/*.jpg` + `TEAM/ann/*.jpg.json`).

Decisions (documented in training/conesight_train/detector/README.md):

- **Class names** come from the data set (`data.yaml`'s `names` beside or above the split
  folder; Supervisely `classTitle`s) and map by name, so any class order works: `blue_cone` /
  `blue`, `yellow_cone` / `yellow`, `orange_cone` / `orange`, `large_orange_cone` /
  `large_orange`. A name we do not know is an error naming the file and the class.
- **`unknown_cone`** (a cone whose colour the labeller could not tell: far, dark, cut) is an
  *ignore region*, not a fifth class and not background: class -1, marked difficult, so
  training neither rewards nor penalises a detection there and the metrics neither count it
  missed nor count a detection lying on it as false (`metrics.py`).
- **The FSOCO watermark border** (~140 px of the original frame, kept in these images) stays:
  labels are in the bordered image's coordinates, the test frames have it too, and the random
  crops of training (`augment.py`) show cones with and without it, so the network learns that
  the border is not part of the scene. Nothing is cut away.
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import yaml

from conesight_train.data.errors import LabelError
from conesight_train.data.supervisely_boxes import read_supervisely_boxes
from conesight_train.data.yolo_txt import CONE_CLASSES, read_yolo_txt
from conesight_train.detector.data import IMAGE_SUFFIXES, LabelledFrame, read_rgb
from conesight_train.detector.model import CLASS_NAMES

if CONE_CLASSES != CLASS_NAMES:  # pragma: no cover - guards the Supervisely mapping below
    raise ImportError("data.yolo_txt.CONE_CLASSES must equal detector.model.CLASS_NAMES")

# Class -1: an ignore region (see the module docs).
IGNORE_CLASS = -1
IGNORED_NAMES = ("unknown_cone", "unknown")


def class_index(name: str, where: Path) -> int:
    """A data set's class name -> our class index, or IGNORE_CLASS for unknown cones."""
    key = name.strip().lower()
    if key in IGNORED_NAMES:
        return IGNORE_CLASS
    if key.endswith("_cone"):
        key = key[: -len("_cone")]
    if key in CLASS_NAMES:
        return CLASS_NAMES.index(key)
    raise LabelError(
        where,
        f"class {name!r} is not a cone class conesight knows; expected one of "
        f"{[f'{n}_cone' for n in CLASS_NAMES]} or unknown_cone",
    )


def yolo_names(split_dir: Path) -> list[str]:
    """The class names of a YOLO split folder: `data.yaml` in it or up to two folders above."""
    for folder in (split_dir, split_dir.parent, split_dir.parent.parent):
        path = folder / "data.yaml"
        if path.is_file():
            try:
                names = yaml.safe_load(path.read_text(encoding="utf-8"))["names"]
            except (OSError, KeyError, TypeError, yaml.YAMLError) as err:
                raise LabelError(path, f"cannot read `names`: {err!r}") from err
            if isinstance(names, dict):
                return [str(names[k]) for k in sorted(names, key=int)]
            return [str(n) for n in names]
    raise LabelError(
        split_dir / "data.yaml",
        "missing: a YOLO folder needs a data.yaml with `names` (here or one or two folders up)",
    )


def _frame(
    image_path: Path, boxes: np.ndarray, classes: np.ndarray, image: np.ndarray
) -> LabelledFrame:
    ignored = classes == IGNORE_CLASS
    return LabelledFrame(
        image,
        boxes.reshape(-1, 4),
        classes,
        np.full(len(classes), np.nan),
        image_path.stem,
        ignored,
    )


class YoloFrames:
    """A YOLO split folder (`images/` + `labels/`); `limit` keeps the first frames (sorted)."""

    def __init__(self, split_dir: str | Path, limit: int | None = None) -> None:
        self.root = Path(split_dir)
        images_dir = self.root / "images"
        if not images_dir.is_dir():
            raise LabelError(images_dir, "missing: a YOLO split folder has images/ and labels/")
        self.images = sorted(p for p in images_dir.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)[
            :limit
        ]
        if not self.images:
            raise LabelError(images_dir, "no images")
        names = yolo_names(self.root)
        self.mapping = [class_index(n, self.root / "data.yaml") for n in names]

    def __len__(self) -> int:
        return len(self.images)

    def label_path(self, index: int) -> Path:
        """The label file of frame `index` (may not exist: a frame with no cones)."""
        return self.root / "labels" / f"{self.images[index].stem}.txt"

    def __getitem__(self, index: int) -> LabelledFrame:
        image_path = self.images[index]
        image = read_rgb(image_path)
        height, width = image.shape[:2]
        label = self.label_path(index)
        boxes = (
            read_yolo_txt(label, width, height, class_count=len(self.mapping))
            if label.is_file()
            else []
        )
        # read_yolo_txt returns OpenCV edges; frames here use continuous pixels (+0.5).
        array = (
            np.array([[b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px] for b in boxes], np.float64)
            + 0.5
        )
        classes = np.array([self.mapping[b.class_id] for b in boxes], np.int64)
        return _frame(image_path, array, classes, image)


class SuperviselyFrames:
    """FSOCO's own layout: every `*/img/*` image with its `*/ann/NAME.json` (team folders)."""

    def __init__(self, root: str | Path, limit: int | None = None) -> None:
        self.root = Path(root)
        self.items: list[tuple[Path, Path]] = []
        for image in sorted(self.root.glob("**/img/*")):
            if image.suffix.lower() not in IMAGE_SUFFIXES:
                continue
            ann = image.parent.parent / "ann" / f"{image.name}.json"
            if not ann.is_file():
                raise LabelError(ann, f"missing: {image.name} needs its Supervisely annotation")
            self.items.append((image, ann))
        self.items = self.items[:limit]
        if not self.items:
            raise LabelError(self.root, "no TEAM/img/* images: is this an FSOCO folder?")

    def __len__(self) -> int:
        return len(self.items)

    def __getitem__(self, index: int) -> LabelledFrame:
        image_path, ann_path = self.items[index]
        ann = read_supervisely_boxes(ann_path)
        image = read_rgb(image_path)
        if image.shape[:2] != (ann.height_px, ann.width_px):
            raise LabelError(
                ann_path,
                f"size {ann.width_px}x{ann.height_px} does not match the image "
                f"{image.shape[1]}x{image.shape[0]}",
            )
        boxes = (
            np.array([[b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px] for b in ann.boxes]) + 0.5
        )
        # The reader's class ids index CONE_CLASSES, which is CLASS_NAMES (same order).
        classes = np.array(
            [IGNORE_CLASS if b.class_id is None else b.class_id for b in ann.boxes], np.int64
        )
        return _frame(image_path, boxes.reshape(-1, 4), classes, image)


def open_real(spec: str, limit: int | None = None) -> YoloFrames | SuperviselyFrames:
    """`yolo:PATH` / `supervisely:PATH`, or a bare path (YOLO when it has images/)."""
    kind, _, path = spec.partition(":") if ":" in spec else ("", "", spec)
    if kind == "supervisely" or (not kind and not (Path(path) / "images").is_dir()):
        return SuperviselyFrames(path, limit)
    return YoloFrames(path, limit)


def describe(source: YoloFrames | SuperviselyFrames) -> dict[str, object]:
    """Frames and boxes per class (ignored ones apart), for logs and cards."""
    counts = dict.fromkeys([*CLASS_NAMES, "ignored"], 0)
    for i in range(len(source)):
        frame = source[i]
        for c in frame.classes:
            counts["ignored" if c < 0 else CLASS_NAMES[c]] += 1
    return {"frames": len(source), "boxes": counts}


if __name__ == "__main__":  # pragma: no cover - a quick look at a folder
    import sys

    print(json.dumps(describe(open_real(sys.argv[1])), indent=2))
