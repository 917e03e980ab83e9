"""Detector geometry: the band rule, targets and decoding invert each other, augmentation keeps
boxes on the cones, label readers."""

import json

import numpy as np
import pytest
import torch

from conesight_train.data.errors import LabelError
from conesight_train.detector.augment import DetectorAugmentParams, to_input
from conesight_train.detector.band import (
    BandParams,
    band_to_input,
    frame_from_input,
    input_from_frame,
)
from conesight_train.detector.data import (
    TOY_BODY_RGB,
    LabelledFrame,
    RendererFrames,
    ToyFrames,
    read_json_labels,
)
from conesight_train.detector.model import STRIDE_PX, decode_boxes, peak_scores
from conesight_train.detector.postprocess import Thresholds, decode
from conesight_train.detector.targets import encode

SMALL_BAND = BandParams(band_top_px=32, input_width_px=128, input_height_px=64, factor=2)


def test_band_is_the_block_mean_of_the_clamped_rows():
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 256, (150, 256, 3), dtype=np.uint8)
    band = BandParams(band_top_px=40, input_width_px=128, input_height_px=64, factor=2)
    x = band_to_input(frame, band)
    top = 150 - 128  # 40 would overrun the 150-row frame: clamped
    assert band.top_for(150) == top
    ref = frame[top : top + 128].astype(np.float64).reshape(64, 2, 128, 2, 3).mean(axis=(1, 3))
    np.testing.assert_allclose(x, ref.transpose(2, 0, 1), atol=1e-4)
    with pytest.raises(ValueError, match="frame width 250 px"):
        band_to_input(frame[:, :250], band)
    with pytest.raises(ValueError, match="below the band height"):
        band_to_input(frame[:100], band)


def test_box_mapping_round_trip():
    boxes = np.array([[10.0, 600.0, 22.0, 633.0], [-0.5, 560.0, 3.0, 1199.5]])
    band = BandParams()
    there = input_from_frame(boxes, band, 560)
    np.testing.assert_allclose(frame_from_input(there, band, 560), boxes, atol=1e-9)
    # Pixel centre 0 of the input is the middle of frame pixels 0 and 1 (OpenCV convention).
    assert there[1, 0] == pytest.approx(-0.5)


def perfect_outputs(boxes, classes, hw):
    """Network outputs that encode the boxes exactly."""
    t = encode(boxes, classes, 4, hw)
    h, w = hw[0] // STRIDE_PX, hw[1] // STRIDE_PX
    logits = torch.full((1, 4, h, w), -10.0)
    reg = torch.zeros(1, 4, h, w)
    for i in range(int(t.mask.sum())):
        cy, cx = divmod(int(t.index[i]), w)
        logits[0, int(classes[i]), cy, cx] = 6.0
        reg[0, :, cy, cx] = torch.from_numpy(t.regression[i])
    return logits, reg


def test_decoding_inverts_targets():
    boxes = np.array([[100.3, 50.2, 121.9, 110.4], [400.0, 200.0, 412.5, 221.0], [30, 30, 36, 44]])
    classes = np.array([1, 3, 0])
    logits, reg = perfect_outputs(boxes, classes, (256, 512))
    out = torch.cat([decode_boxes(reg), peak_scores(logits)], 1).flatten(2)[0].numpy()
    dets = decode(out, Thresholds(score_threshold=0.5))
    assert len(dets) == 3
    order = np.argsort(dets[:, 0])
    np.testing.assert_allclose(dets[order, :4], boxes[[2, 0, 1]], atol=1e-3)
    assert dets[order, 5].tolist() == [0.0, 1.0, 3.0]


def test_targets_are_tall_gaussians_with_one_peak_per_box():
    t = encode(np.array([[40.0, 20.0, 52.0, 60.0]]), np.array([2]), 4, (128, 128))
    assert t.heat[2].max() == 1.0 and (t.heat == 1.0).sum() == 1
    ys, xs = np.nonzero(t.heat[2] > 0.3)
    assert np.ptp(ys) > np.ptp(xs)  # taller than wide, like the cone
    assert t.heat[[0, 1, 3]].max() == 0.0
    # A box below MIN_BOX_PX is not a positive, but its cells are left out of the negatives.
    tiny = encode(np.array([[10.0, 10.0, 11.0, 13.0]]), np.array([0]), 4, (64, 64))
    assert tiny.mask.sum() == 0 and tiny.ignore.sum() > 0


def test_augmented_boxes_stay_on_the_cones():
    frames = ToyFrames(40, seed=3, cones_per_frame=3)
    params = DetectorAugmentParams(
        photometric=DetectorAugmentParams().photometric.__class__(
            p_colour=0, p_gamma=0, p_blur=0, p_noise=0, p_jpeg=0
        )
    )
    checked = 0
    for i in range(len(frames)):
        for seed in range(4):
            sample = to_input(frames[i], SMALL_BAND, np.random.default_rng(seed), params)
            img = sample.image.transpose(1, 2, 0)
            for box, cls in zip(sample.boxes_px, sample.classes, strict=True):
                h = box[3] - box[1]
                if h < 14 or box[3] >= 63 or box[0] <= 1 or box[2] >= 127:
                    continue  # small or clipped: the sampled pixel may be an edge
                x, y = int((box[0] + box[2]) / 2), int(box[3] - 0.15 * h)
                assert np.abs(img[y, x] - np.array(TOY_BODY_RGB[cls])).max() < 40, (i, seed, box)
                checked += 1
    assert checked > 10


def test_json_and_yolo_readers(tmp_path):
    (tmp_path / "images").mkdir()
    (tmp_path / "annotations").mkdir()
    import cv2

    cv2.imwrite(str(tmp_path / "images/000000.png"), np.zeros((20, 30, 3), np.uint8))
    record = {
        "image": "images/000000.png",
        "cones": [
            {
                "class_id": 3,
                "bbox": {"x_min_px": 1.5, "y_min_px": 2.5, "x_max_px": 9.5, "y_max_px": 18.5},
                "range_m": 7.25,
            }
        ],
    }
    (tmp_path / "annotations/000000.json").write_text(json.dumps(record))
    frame = RendererFrames(tmp_path)[0]
    np.testing.assert_allclose(frame.boxes_px, [[2.0, 3.0, 10.0, 19.0]])
    assert frame.classes.tolist() == [3] and frame.range_m.tolist() == [7.25]
    (tmp_path / "annotations/000000.json").write_text(json.dumps({"image": "x", "cones": [{}]}))
    with pytest.raises(LabelError, match="not a conesight frame record"):
        read_json_labels(tmp_path / "annotations/000000.json")
    (tmp_path / "annotations/000000.json").unlink()
    (tmp_path / "labels").mkdir()
    (tmp_path / "labels/000000.txt").write_text("1 0.5 0.5 0.2 0.5\n")
    frame = RendererFrames(tmp_path)[0]
    np.testing.assert_allclose(frame.boxes_px, [[12.0, 5.0, 18.0, 15.0]])
    assert np.isnan(frame.range_m).all()


def test_toy_frames_are_seeded():
    a, b = ToyFrames(2, seed=5)[1], ToyFrames(2, seed=5)[1]
    assert isinstance(a, LabelledFrame)
    np.testing.assert_array_equal(a.image_rgb, b.image_rgb)
    np.testing.assert_array_equal(a.boxes_px, b.boxes_px)


def quaternion_xyzw(r):
    """Rotation matrix -> (x, y, z, w), for proper rotations with trace > -1."""
    w = np.sqrt(1.0 + np.trace(r)) / 2
    return [
        (r[2, 1] - r[1, 2]) / (4 * w),
        (r[0, 2] - r[2, 0]) / (4 * w),
        (r[1, 0] - r[0, 1]) / (4 * w),
        w,
    ]


def test_horizon_follows_the_pitch(tmp_path):
    from conesight_train.detector.band import HORIZON_MARGIN_PX, band_top_from
    from conesight_train.detector.data import horizon_from_calibration

    # vehicle_from_camera of a level camera: camera z = vehicle x, camera x = -y, camera y = -z.
    level = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    pitch = 0.1  # looking down
    c, s = np.cos(pitch), np.sin(pitch)
    about_y = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    (tmp_path / "info.yaml").write_text(
        "camera_matrix:\n  data: [2000.0, 0.0, 960.0, 0.0, 2000.0, 600.0, 0.0, 0.0, 1.0]\n"
    )
    for rotation, want in ((level, 600.0), (about_y @ level, 600.0 - 2000.0 * np.tan(pitch))):
        q = [float(v) for v in quaternion_xyzw(rotation)]
        (tmp_path / "ext.yaml").write_text(
            f"vehicle_from_camera:\n  translation_m: [0, 0, 1]\n  rotation_xyzw: {q}\n"
        )
        got = horizon_from_calibration(tmp_path / "info.yaml", tmp_path / "ext.yaml")
        assert got == pytest.approx(want, abs=1e-6)
    # conesight-core's current form: the camera body's rotation (pitch about vehicle y).
    for text in (
        f"vehicle_from_camera:\n  translation_m: [0, 0, 1]\n  rotation:\n"
        f"    quaternion_xyzw: [0.0, {np.sin(pitch / 2)}, 0.0, {np.cos(pitch / 2)}]\n",
        f"vehicle_from_camera:\n  translation_m: [0, 0, 1]\n  rotation:\n"
        f"    rpy_rad: [0.0, {pitch}, 0.0]\n",
        f"vehicle_from_camera: {{height_m: 1.0, pitch_down_rad: {pitch}}}\n",
    ):
        (tmp_path / "ext.yaml").write_text(text)
        got = horizon_from_calibration(tmp_path / "info.yaml", tmp_path / "ext.yaml")
        assert got == pytest.approx(600.0 - 2000.0 * np.tan(pitch), abs=1e-6), text
    assert band_top_from(600.0) == 600 - HORIZON_MARGIN_PX == BandParams().band_top_px
