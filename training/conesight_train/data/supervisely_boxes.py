"""Reader for FSOCO's Supervisely JSON box labels (`ann/NAME.json` per image).

Each object with `geometryType` "rectangle" has `points.exterior = [[left, top], [right,
bottom]]` in inclusive pixel indices, converted here to continuous edges (OpenCV convention:
`x_min_px = left - 0.5`, `x_max_px = right + 0.5`). FSOCO class titles map to conesight's
detector classes; `unknown_cone` is kept with class None (mask it or drop it when training).
Other geometry types (FSOCO also ships polygons and bitmaps in its segmentation release) or
unknown class titles raise `LabelError` naming the file and the object index.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path

from conesight_train.data.errors import LabelError
from conesight_train.data.yolo_txt import CONE_CLASSES

FSOCO_CLASS_TO_CONESIGHT: dict[str, str | None] = {
    "blue_cone": "blue",
    "yellow_cone": "yellow",
    "orange_cone": "orange",
    "large_orange_cone": "large_orange",
    "unknown_cone": None,
}


@dataclass(frozen=True)
class LabelledBox:
    """One box in pixels (continuous edges); `class_id` indexes CONE_CLASSES, None = unknown."""

    class_id: int | None
    x_min_px: float
    y_min_px: float
    x_max_px: float
    y_max_px: float
    object_index: int


@dataclass(frozen=True)
class BoxAnnotation:
    """An image's size and boxes."""

    width_px: int
    height_px: int
    boxes: list[LabelledBox]


def read_supervisely_boxes(path: str | Path) -> BoxAnnotation:
    """Reads one Supervisely annotation file of boxes."""
    path = Path(path)
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except json.JSONDecodeError as err:
        raise LabelError(path, f"not valid JSON: {err.msg}", line=err.lineno) from err
    try:
        width, height = int(data["size"]["width"]), int(data["size"]["height"])
        objects = list(data["objects"])
    except (KeyError, TypeError, ValueError) as err:
        raise LabelError(path, f"missing or malformed 'size'/'objects': {err!r}") from err
    boxes = []
    for index, obj in enumerate(objects):
        where = f"object {index}"
        if not isinstance(obj, dict):
            raise LabelError(path, f"{where}: not an object")
        title = obj.get("classTitle")
        if title not in FSOCO_CLASS_TO_CONESIGHT:
            known = sorted(FSOCO_CLASS_TO_CONESIGHT)
            raise LabelError(path, f"{where}: unknown class {title!r}; expected one of {known}")
        if obj.get("geometryType") != "rectangle":
            raise LabelError(
                path, f"{where}: geometryType {obj.get('geometryType')!r}, expected 'rectangle'"
            )
        try:
            (left, top), (right, bottom) = obj["points"]["exterior"]
            left, top, right, bottom = float(left), float(top), float(right), float(bottom)
        except (KeyError, TypeError, ValueError) as err:
            raise LabelError(
                path, f"{where}: expected exterior [[l, t], [r, b]] ({err!r})"
            ) from err
        x0, x1 = sorted((left, right))
        y0, y1 = sorted((top, bottom))
        name = FSOCO_CLASS_TO_CONESIGHT[title]
        class_id = CONE_CLASSES.index(name) if name is not None else None
        boxes.append(LabelledBox(class_id, x0 - 0.5, y0 - 0.5, x1 + 0.5, y1 + 0.5, index))
    return BoxAnnotation(width, height, boxes)
