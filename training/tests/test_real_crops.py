"""Real keypoint crops: both layouts, the split by source frame, the data spec, training use."""

import json
from pathlib import Path

import cv2
import numpy as np
import pytest

from conesight_train.data.errors import LabelError
from conesight_train.data.real_crops import (
    frame_split,
    parse_real_spec,
    read_real_crops,
    source_frame,
    split_crops,
)
from conesight_train.train_keypoints import open_source

SHARED = Path(__file__).resolve().parents[3] / "shared" / "data"
KEYPOINTS = [[20, 4], [15, 20], [12, 30], [9, 45], [25, 20], [28, 30], [31, 45]]


def write_keypoints_json(root: Path, frames: list[int]) -> None:
    (root / "img").mkdir(parents=True)
    entries = []
    for i, frame in enumerate(frames):
        name = f"img/amz_{frame:05d}_{i}_0_40_50.jpg"
        cv2.imwrite(str(root / name), np.full((50, 40, 3), 90, np.uint8))
        entries.append({"image": name, "width_px": 40, "height_px": 50, "keypoints_px": KEYPOINTS})
    (root / "keypoints.json").write_text(json.dumps(entries))


def test_split_is_by_frame_and_covers_every_crop(tmp_path):
    write_keypoints_json(tmp_path, [f for f in range(60) for _ in range(2)])
    crops = read_real_crops(tmp_path)
    parts = {s: split_crops(crops, s) for s in ("train", "val", "calib")}
    assert sum(len(p) for p in parts.values()) == len(crops) == 120
    frames = {s: {source_frame(c.image_path) for c in p} for s, p in parts.items()}
    assert not frames["train"] & frames["val"] and not frames["train"] & frames["calib"]
    assert not frames["val"] & frames["calib"]
    assert all(len(p) > 0 for p in parts.values())
    assert frame_split("amz_00007") == frame_split("amz_00007")


def test_spec_parsing_and_repeat(tmp_path):
    assert parse_real_spec("real:/a/b:val*3") == (Path("/a/b"), "val", 3)
    assert parse_real_spec("real:/a/b") == (Path("/a/b"), "all", 1)
    with pytest.raises(ValueError, match="repeat"):
        parse_real_spec("real:/a:train*x")
    write_keypoints_json(tmp_path, list(range(40)))
    all_crops = open_source(f"real:{tmp_path}:all")
    twice = open_source(f"real:{tmp_path}:all*2")
    assert len(twice) == 2 * len(all_crops) == 80
    sample = twice[41]
    assert sample.patch_rgb.shape == (80, 80, 3)
    np.testing.assert_allclose(sample.keypoints_px, all_crops[1].keypoints_px)


def test_bad_files_name_the_file(tmp_path):
    with pytest.raises(LabelError, match=r"keypoints\.json"):
        read_real_crops(tmp_path)
    (tmp_path / "keypoints.json").write_text('[{"image": "img/x.jpg"}]')
    with pytest.raises(LabelError, match="crop 0"):
        read_real_crops(tmp_path)
    with pytest.raises(LabelError, match="cannot split"):
        source_frame(Path("cone.png"))


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data is absent")
def test_shared_crops_split_into_three_parts():
    for root in (
        SHARED / "real-dev" / "fsoco-keypoint-crops",
        SHARED / "real-train" / "amz-keypoint-crops-hires",
    ):
        crops = read_real_crops(root)
        sizes = [len(split_crops(crops, s)) for s in ("train", "val", "calib")]
        assert sum(sizes) == len(crops) > 600
        assert 0.08 < sizes[1] / len(crops) < 0.25 and 0.04 < sizes[2] / len(crops) < 0.2
