"""Detector data: labelled frames from the renderer (our JSON or YOLO txt) and procedural toy
frames for tests.

A `LabelledFrame` is a full frame (HxWx3 uint8 RGB) with boxes [M, 4] in continuous frame
pixels (the image spans [0, W] x [0, H]; OpenCV edges + 0.5), classes [M] (indices of
CLASS_NAMES) and range_m [M] (NaN when the labels have no distances).

Renderer layout (crates/conesight-sim writers): `images/NNNNNN.png|jpg`, and either
`annotations/NNNNNN.json` (ours: `cones[*].class_id`, `.bbox.{x_min_px, ...}` OpenCV edges,
`.range_m`) or `labels/NNNNNN.txt` (YOLO). JSON is preferred when both exist (it has ranges);
with it, `camera_info/` and `extrinsics/` give each frame's calibration (flat-ground ranges of
detections for the metrics, `ground.py`). Real labelled frames: `real_frames.py`.
"""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import Protocol

import cv2
import numpy as np
import yaml

from conesight_train.data.errors import LabelError
from conesight_train.data.yolo_txt import read_yolo_txt
from conesight_train.detector.ground import GroundCamera
from conesight_train.detector.model import CLASS_NAMES

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg")
# Toy cone colours (RGB) per class, and their stripe colour.
TOY_BODY_RGB = ((20, 60, 200), (235, 200, 20), (240, 110, 20), (240, 110, 20))
TOY_STRIPE_RGB = ((240, 240, 240), (20, 20, 20), (240, 240, 240), (240, 240, 240))
TOY_ASPECT = (0.7, 0.7, 0.7, 0.56)  # base width / height
# Cones the metrics skip and training neither rewards nor penalises (VOC's "difficult").
DIFFICULT_MIN_HEIGHT_PX = 4.0
DIFFICULT_OCCLUSION = 0.6
# More than half of the cone outside the image (KITTI's limit for its hardest level): the
# keypoint network and the PnP need the whole silhouette, and a cone cut at the frame edge is
# seen whole a few frames earlier.
DIFFICULT_TRUNCATION = 0.5


def is_difficult(height_px: float, occlusion: float, truncation: float) -> bool:
    """The one rule for cones that training neither rewards nor penalises and the metrics skip:
    under DIFFICULT_MIN_HEIGHT_PX tall, more than DIFFICULT_OCCLUSION occluded or more than
    DIFFICULT_TRUNCATION truncated by the image border."""
    return (
        height_px < DIFFICULT_MIN_HEIGHT_PX
        or occlusion > DIFFICULT_OCCLUSION
        or truncation > DIFFICULT_TRUNCATION
    )


@dataclass(frozen=True)
class LabelledFrame:
    """A frame with its cones (see the module docs for the conventions)."""

    image_rgb: np.ndarray
    boxes_px: np.ndarray
    classes: np.ndarray
    range_m: np.ndarray
    name: str = ""
    difficult: np.ndarray | None = None  # bool [M]; None = none difficult
    ground: GroundCamera | None = None  # the frame's calibration, when known

    def difficult_mask(self) -> np.ndarray:
        """Bool [M]: cones neither trained as positives nor counted by the metrics."""
        if self.difficult is None:
            return np.zeros(len(self.classes), bool)
        return self.difficult


class FrameSource(Protocol):
    """Indexable labelled frames."""

    def __len__(self) -> int: ...

    def __getitem__(self, index: int) -> LabelledFrame: ...


def read_rgb(path: Path) -> np.ndarray:
    """An image file as HxWx3 uint8 RGB; LabelError when unreadable."""
    bgr = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if bgr is None:
        raise LabelError(path, "cannot read the image")
    return np.ascontiguousarray(bgr[:, :, ::-1])


# Camera (OpenCV) axes -> vehicle axes for a camera looking straight ahead (conesight-core's
# `Extrinsics::optical_to_vehicle_rotation`).
OPTICAL_TO_VEHICLE = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])


def rotation_from_quaternion(x: float, y: float, z: float, w: float) -> np.ndarray:
    """3x3 rotation of a quaternion (normalised first)."""
    n = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


def rotation_from_rpy(roll: float, pitch: float, yaw: float) -> np.ndarray:
    """ROS fixed-axis roll, pitch, yaw: Rz(yaw) Ry(pitch) Rx(roll)."""
    cr, sr, cp, sp, cy, sy = (
        np.cos(roll),
        np.sin(roll),
        np.cos(pitch),
        np.sin(pitch),
        np.cos(yaw),
        np.sin(yaw),
    )
    rz = np.array([[cy, -sy, 0], [sy, cy, 0], [0, 0, 1]])
    ry = np.array([[cp, 0, sp], [0, 1, 0], [-sp, 0, cp]])
    rx = np.array([[1, 0, 0], [0, cr, -sr], [0, sr, cr]])
    return rz @ ry @ rx


def vehicle_from_camera_rotation(pose: dict) -> np.ndarray:
    """The rotation of an extrinsics file's `vehicle_from_camera`, in any of conesight-core's
    forms: `rotation: {quaternion_xyzw | rpy_rad}` (camera body; optical axes composed on
    top), `{height_m, pitch_down_rad}`, or the older full `rotation_xyzw`."""
    if "rotation_xyzw" in pose:
        return rotation_from_quaternion(*map(float, pose["rotation_xyzw"]))
    if "pitch_down_rad" in pose:
        body = rotation_from_rpy(0.0, float(pose["pitch_down_rad"]), 0.0)
    elif "quaternion_xyzw" in pose["rotation"]:
        body = rotation_from_quaternion(*map(float, pose["rotation"]["quaternion_xyzw"]))
    else:
        body = rotation_from_rpy(*map(float, pose["rotation"]["rpy_rad"]))
    return body @ OPTICAL_TO_VEHICLE


def ground_camera_from_calibration(camera_info: Path, extrinsics: Path) -> GroundCamera:
    """The frame's calibration (renderer format) as a `GroundCamera`."""
    try:
        info = yaml.safe_load(camera_info.read_text(encoding="utf-8"))
        k = np.asarray(info["camera_matrix"]["data"], np.float64).reshape(3, 3)
        dist = np.asarray(info.get("distortion_coefficients", {}).get("data", [0.0] * 5))
        pose = yaml.safe_load(extrinsics.read_text(encoding="utf-8"))["vehicle_from_camera"]
        rotation = vehicle_from_camera_rotation(pose)
        if "height_m" in pose:  # the {height_m, pitch_down_rad} form: above the vehicle origin
            translation = np.array([0.0, 0.0, float(pose["height_m"])])
        else:
            translation = np.asarray(pose["translation_m"], np.float64).reshape(3)
    except (OSError, KeyError, TypeError, ValueError, yaml.YAMLError) as err:
        raise LabelError(extrinsics, f"cannot read the calibration: {err!r}") from err
    return GroundCamera(k, dist.astype(np.float64), rotation, translation)


def read_json_labels(
    path: Path,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, str]:
    """Our per-frame JSON -> (boxes [M, 4] continuous px, classes [M], range_m [M],
    difficult [M], image). Difficult: `is_difficult` (the YOLO writer's own height cut,
    occlusion, truncation)."""
    try:
        record = json.loads(path.read_text(encoding="utf-8"))
        boxes, classes, ranges, difficult = [], [], [], []
        for cone in record["cones"]:
            b = cone["bbox"]
            boxes.append([b["x_min_px"], b["y_min_px"], b["x_max_px"], b["y_max_px"]])
            classes.append(int(cone["class_id"]))
            ranges.append(float(cone.get("range_m", np.nan)))
            difficult.append(
                is_difficult(
                    b["y_max_px"] - b["y_min_px"],
                    float(cone.get("occlusion", 0.0)),
                    float(cone.get("truncation", 0.0)),
                )
            )
        image = str(record["image"])
    except (KeyError, TypeError, ValueError) as err:
        raise LabelError(path, f"not a conesight frame record: {err!r}") from err
    cls = np.array(classes, np.int64)
    if np.any((cls < 0) | (cls >= len(CLASS_NAMES))):
        raise LabelError(path, f"class_id outside 0..{len(CLASS_NAMES) - 1}")
    box = np.array(boxes, np.float64).reshape(-1, 4) + 0.5
    return box, cls, np.array(ranges, np.float64), np.array(difficult, bool), image


class RendererFrames:
    """A renderer output folder (see the module docs); `limit` keeps the first frames."""

    def __init__(self, root: str | Path, limit: int | None = None) -> None:
        self.root = Path(root)
        images = sorted(p for p in (self.root / "images").glob("*") if p.suffix in IMAGE_SUFFIXES)
        if not images:
            raise LabelError(self.root / "images", "no images; is this a renderer output folder?")
        self.items: list[tuple[Path, Path]] = []
        for image in images[:limit]:
            label = self.root / "annotations" / f"{image.stem}.json"
            if not label.is_file():
                label = self.root / "labels" / f"{image.stem}.txt"
            if not label.is_file():
                raise LabelError(
                    label, f"missing: {image.name} needs annotations/*.json or labels/*.txt"
                )
            self.items.append((image, label))

    def __len__(self) -> int:
        return len(self.items)

    def frame_classes(self, index: int) -> np.ndarray:
        """The classes of a frame's trainable cones, from its label file alone."""
        _, label_path = self.items[index]
        if label_path.suffix == ".json":
            _, classes, _, difficult, _ = read_json_labels(label_path)
            return classes[~difficult]
        # YOLO boxes are normalised: the image size does not change their classes.
        return np.array([b.class_id for b in read_yolo_txt(label_path, 1, 1)], np.int64)

    def __getitem__(self, index: int) -> LabelledFrame:
        image_path, label_path = self.items[index]
        image = read_rgb(image_path)
        height, width = image.shape[:2]
        ground = None
        if label_path.suffix == ".json":
            boxes, classes, ranges, difficult, _ = read_json_labels(label_path)
            stem = image_path.stem
            camera_info = self.root / "camera_info" / f"{stem}.yaml"
            extrinsics = self.root / "extrinsics" / f"{stem}.yaml"
            if camera_info.is_file() and extrinsics.is_file():
                ground = ground_camera_from_calibration(camera_info, extrinsics)
        else:
            yolo = read_yolo_txt(label_path, width, height)
            boxes = (
                np.array(
                    [[b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px] for b in yolo], np.float64
                ).reshape(-1, 4)
                + 0.5
            )
            classes = np.array([b.class_id for b in yolo], np.int64)
            ranges = np.full(len(yolo), np.nan)
            difficult = np.zeros(len(yolo), bool)
        return LabelledFrame(image, boxes, classes, ranges, image_path.stem, difficult, ground)


def draw_toy_cone(
    image: np.ndarray, cls: int, x_centre: float, y_base: float, height: float
) -> np.ndarray:
    """Draws a striped trapezoid cone; returns its box [4] (continuous px, before clipping)."""
    width = TOY_ASPECT[cls] * height
    top_w = 0.15 * width
    pts = np.array(
        [
            [x_centre - width / 2, y_base],
            [x_centre + width / 2, y_base],
            [x_centre + top_w / 2, y_base - height],
            [x_centre - top_w / 2, y_base - height],
        ]
    )
    shift = 4
    scale = 1 << shift
    cv2.fillPoly(
        image, [np.round(pts * scale).astype(np.int32)], TOY_BODY_RGB[cls], cv2.LINE_AA, shift
    )
    for lo, hi in ((0.35, 0.5),) if cls != 3 else ((0.3, 0.4), (0.55, 0.65)):
        w_lo = width + (top_w - width) * lo
        w_hi = width + (top_w - width) * hi
        stripe = np.array(
            [
                [x_centre - w_lo / 2, y_base - lo * height],
                [x_centre + w_lo / 2, y_base - lo * height],
                [x_centre + w_hi / 2, y_base - hi * height],
                [x_centre - w_hi / 2, y_base - hi * height],
            ]
        )
        cv2.fillPoly(
            image,
            [np.round(stripe * scale).astype(np.int32)],
            TOY_STRIPE_RGB[cls],
            cv2.LINE_AA,
            shift,
        )
    return np.array([x_centre - width / 2, y_base - height, x_centre + width / 2, y_base])


class ToyFrames:
    """Procedural frames (tests, smoke runs): ground below a horizon row, cones on it whose
    height shrinks with distance like a pinhole camera's (`focal_px` / range x 0.33 m)."""

    def __init__(
        self,
        count: int,
        seed: int,
        size_wh: tuple[int, int] = (256, 160),
        horizon_px: float = 40.0,
        focal_px: float = 260.0,
        cones_per_frame: int = 8,
    ) -> None:
        self.count = count
        self.seed = seed
        self.size_wh = size_wh
        self.horizon_px = horizon_px
        self.focal_px = focal_px
        self.cones_per_frame = cones_per_frame

    def __len__(self) -> int:
        return self.count

    def __getitem__(self, index: int) -> LabelledFrame:
        rng = np.random.default_rng([self.seed, index])
        w, h = self.size_wh
        image = np.empty((h, w, 3), np.uint8)
        image[:] = rng.integers(120, 220, 3)
        image[int(self.horizon_px) :] = rng.integers(40, 110, 3)
        noise = rng.normal(0, 6, image.shape)
        image = np.clip(image + noise, 0, 255).astype(np.uint8)
        camera_h_m = 1.0
        cones = []
        for _ in range(self.cones_per_frame):
            range_m = float(rng.uniform(2.5, 25.0))
            cls = int(rng.integers(len(CLASS_NAMES)))
            height = self.focal_px * (0.505 if cls == 3 else 0.325) / range_m
            y_base = self.horizon_px + self.focal_px * camera_h_m / range_m
            cones.append((range_m, cls, float(rng.uniform(0, w)), y_base, height))
        boxes, classes, ranges = [], [], []
        for range_m, cls, x, y_base, height in sorted(cones, key=lambda c: -c[0]):
            box = draw_toy_cone(image, cls, x, y_base, height)
            clipped = np.clip(box, 0, [w, h, w, h])
            if clipped[2] - clipped[0] > 1 and clipped[3] - clipped[1] > 1:
                boxes.append(clipped)
                classes.append(cls)
                ranges.append(range_m)
        return LabelledFrame(
            image,
            np.array(boxes, np.float64).reshape(-1, 4),
            np.array(classes, np.int64),
            np.array(ranges, np.float64),
            f"toy_{index:06d}",
        )
