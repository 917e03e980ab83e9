"""Label readers: real Supervisely crops, RektNet CSV, YOLO txt, the renderer's patch index."""

import json
from pathlib import Path

import numpy as np
import pytest

from conesight_train.data.errors import LabelError
from conesight_train.data.patches import RealCropPatches
from conesight_train.data.rektnet_csv import read_rektnet_csv
from conesight_train.data.sim_patches import read_patch_index
from conesight_train.data.supervisely_boxes import read_supervisely_boxes
from conesight_train.data.supervisely_keypoints import read_keypoint_crops
from conesight_train.data.yolo_txt import read_yolo_txt

REPO_ROOT = Path(__file__).resolve().parents[2]
REAL_CROPS = REPO_ROOT.parent / "shared" / "data" / "real-dev" / "fsoco-keypoint-crops"


@pytest.fixture(scope="module")
def real_crops():
    if not REAL_CROPS.is_dir():
        pytest.skip(f"real crops not present at {REAL_CROPS}")
    return read_keypoint_crops(REAL_CROPS)


def test_real_crops_read_with_conesight_order(real_crops):
    crops = real_crops.crops
    total = len(crops) + len(real_crops.skipped_point_count)
    assert total == len(list((REAL_CROPS / "ann").glob("*.json")))
    assert len(crops) > 1900
    assert 0 < len(real_crops.skipped_point_count) < 50
    k = np.stack([c.keypoints_px for c in crops])  # (M, 7, 2)
    # Apex highest; each side runs top to bottom; left side left of the right side.
    assert np.mean(k[:, 0, 1] < k[:, [1, 4], 1].min(axis=1)) > 0.98
    for upper, lower, base in [(1, 2, 3), (4, 5, 6)]:
        assert np.mean((k[:, upper, 1] < k[:, lower, 1]) & (k[:, lower, 1] < k[:, base, 1])) > 0.98
    assert np.mean(k[:, [1, 2, 3], 0] < k[:, [4, 5, 6], 0]) > 0.98


def test_real_crops_map_into_80x80_patches(real_crops):
    patches = RealCropPatches(real_crops.crops[:20])
    filled = RealCropPatches(real_crops.crops[:20], outside="fill")
    # Same geometry either way; replicate leaves no black side bands, fill does.
    np.testing.assert_allclose(patches[3].keypoints_px, filled[3].keypoints_px, atol=1e-9)
    assert patches[3].patch_rgb[:, :4].mean() > 30 and filled[3].patch_rgb[:, :4].max() == 0
    for i in range(len(patches)):
        sample = patches[i]
        assert sample.patch_rgb.shape == (80, 80, 3)
        assert (sample.keypoints_px > 0).all() and (sample.keypoints_px < 79).all()
    # A 48x64 crop is a box of 64 px; the patch covers 64 * 1.2 px, so 0.96 crop px per patch px.
    first = real_crops.crops[0]
    mapped = patches[0].keypoints_px
    np.testing.assert_allclose(
        np.diff(mapped[:, 1]), np.diff(first.keypoints_px[:, 1]) / 0.96, atol=1e-4
    )


def _write_supervisely(root: Path, objects: list) -> None:
    (root / "ann").mkdir(parents=True)
    (root / "img").mkdir()
    (root / "img" / "a.png").write_bytes(b"")
    ann = {"size": {"width": 48, "height": 64}, "tags": [], "objects": objects}
    (root / "ann" / "a.png.json").write_text(json.dumps(ann))


def test_supervisely_reorders_and_counts_skipped(tmp_path):
    objects = [{"points": {"exterior": [[i, 10 * i]]}} for i in range(7)]
    _write_supervisely(tmp_path / "good", objects)
    crops = read_keypoint_crops(tmp_path / "good")
    assert crops.crops[0].keypoints_px[:, 0].tolist() == [3, 4, 5, 6, 2, 1, 0]
    _write_supervisely(tmp_path / "short", objects[:6])
    short = read_keypoint_crops(tmp_path / "short")
    assert short.crops == [] and len(short.skipped_point_count) == 1


def test_supervisely_malformed_point_names_the_file(tmp_path):
    objects = [{"points": {"exterior": [[i, 10 * i]]}} for i in range(7)]
    objects[4] = {"points": {"exterior": []}}
    _write_supervisely(tmp_path, objects)
    with pytest.raises(LabelError, match=r"a\.png\.json: object 4"):
        read_keypoint_crops(tmp_path)


REKTNET_HEADER = ",Name,URL,top,mid_L_top,mid_R_top,mid_L_bot,mid_R_bot,bot_L,bot_R\n"


def test_rektnet_csv_maps_columns_to_conesight_order(tmp_path):
    path = tmp_path / "labels.csv"
    cells = '"[10, 1]","[8, 5]","[12, 5]","[7, 9]","[13, 9]","[5, 15]","[15, 15]"'
    row = f"0,c1.jpg,http://x/c1.jpg,{cells}\n"
    path.write_text(REKTNET_HEADER + row)
    rows = read_rektnet_csv(path)
    assert rows[0].image == "c1.jpg" and rows[0].line == 2
    np.testing.assert_array_equal(
        rows[0].keypoints_px, [[10, 1], [8, 5], [7, 9], [5, 15], [12, 5], [13, 9], [15, 15]]
    )


@pytest.mark.parametrize(
    ("cell", "message"),
    [('"[8; 5]"', "mid_L_top"), ('"[8, x]"', "not numbers"), ('"[8, nan]"', "non-finite")],
)
def test_rektnet_malformed_cell_names_file_and_line(tmp_path, cell, message):
    path = tmp_path / "labels.csv"
    good = '0,c1.jpg,u,"[10, 1]","[8, 5]","[12, 5]","[7, 9]","[13, 9]","[5, 15]","[15, 15]"\n'
    bad = f'1,c2.jpg,u,"[10, 1]",{cell},"[12, 5]","[7, 9]","[13, 9]","[5, 15]","[15, 15]"\n'
    path.write_text(REKTNET_HEADER + good + bad)
    with pytest.raises(LabelError, match=rf"labels\.csv:3: .*{message}"):
        read_rektnet_csv(path)


def test_rektnet_missing_column_is_an_error(tmp_path):
    path = tmp_path / "labels.csv"
    path.write_text('Name,top,mid_L_top\nc.jpg,"[1, 2]","[3, 4]"\n')
    with pytest.raises(LabelError, match=r"labels\.csv:1: header lacks"):
        read_rektnet_csv(path)


def test_yolo_boxes_in_pixel_edges(tmp_path):
    path = tmp_path / "000001.txt"
    path.write_text("0 0.5 0.5 0.5 0.25\n\n3 0.25 0.75 0.1 0.1\n")
    boxes = read_yolo_txt(path, width_px=200, height_px=100)
    assert [b.class_id for b in boxes] == [0, 3]
    b = boxes[0]
    assert (b.x_min_px, b.y_min_px, b.x_max_px, b.y_max_px) == (49.5, 37.0, 149.5, 62.0)
    assert boxes[1].line == 3


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("0 0.5 0.5 0.5\n", "got 4 fields"),
        ("0 0.5 0.5 zero 0.1\n", "not numbers"),
        ("7 0.5 0.5 0.1 0.1\n", "class id 7"),
        ("1 1.5 0.5 0.1 0.1\n", "fractions"),
        ("1 0.5 0.5 0.0 0.1\n", "empty box"),
    ],
)
def test_yolo_malformed_names_file_and_line(tmp_path, text, message):
    path = tmp_path / "frame.txt"
    path.write_text("0 0.5 0.5 0.1 0.1\n" + text)
    with pytest.raises(LabelError, match=rf"frame\.txt:2: .*{message}"):
        read_yolo_txt(path, 640, 480)


def test_patch_index_reads_and_rejects_bad_lines(tmp_path):
    (tmp_path / "patches").mkdir()
    kp = [[float(i), float(2 * i)] for i in range(7)]
    good = json.dumps({"file": "patches/000000_000.png", "keypoints_px": kp, "class": "blue"})
    (tmp_path / "patches" / "index.jsonl").write_text(good + "\n")
    records = read_patch_index(tmp_path)
    assert records[0].extra == {"class": "blue"}
    assert records[0].image_path == tmp_path / "patches" / "000000_000.png"
    bad = json.dumps({"file": "x.png", "keypoints_px": kp[:6]})
    (tmp_path / "patches" / "index.jsonl").write_text(good + "\n" + bad + "\n")
    with pytest.raises(LabelError, match=r"index\.jsonl:2: keypoints_px must be 7"):
        read_patch_index(tmp_path)


def _box(title, exterior, geometry="rectangle"):
    return {"classTitle": title, "geometryType": geometry, "points": {"exterior": exterior}}


def test_supervisely_boxes_map_classes_and_edges(tmp_path):
    path = tmp_path / "img.png.json"
    objects = [_box("yellow_cone", [[10, 20], [19, 49]]), _box("unknown_cone", [[5, 5], [1, 1]])]
    path.write_text(json.dumps({"size": {"width": 64, "height": 64}, "objects": objects}))
    ann = read_supervisely_boxes(path)
    first, second = ann.boxes
    assert first.class_id == 1
    assert (first.x_min_px, first.y_min_px, first.x_max_px, first.y_max_px) == (
        9.5,
        19.5,
        19.5,
        49.5,
    )
    assert second.class_id is None and second.x_min_px == 0.5


@pytest.mark.parametrize(
    ("obj", "message"),
    [
        (_box("red_cone", [[0, 0], [1, 1]]), "object 1: unknown class 'red_cone'"),
        (_box("blue_cone", [[0, 0], [1, 1]], "polygon"), "object 1: geometryType 'polygon'"),
        (_box("blue_cone", [[0, 0]]), "object 1: expected exterior"),
    ],
)
def test_supervisely_boxes_malformed_names_file_and_object(tmp_path, obj, message):
    path = tmp_path / "img.png.json"
    objects = [_box("blue_cone", [[0, 0], [3, 3]]), obj]
    path.write_text(json.dumps({"size": {"width": 8, "height": 8}, "objects": objects}))
    with pytest.raises(LabelError, match=rf"img\.png\.json: {message}"):
        read_supervisely_boxes(path)
