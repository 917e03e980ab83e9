"""Detector geometry: the whole-frame input rule, targets and decoding invert each other,
training crops keep boxes on the cones, label readers."""

import json

import numpy as np
import pytest
import torch

from conesight_train.data.errors import LabelError
from conesight_train.detector.augment import DetectorAugmentParams, to_input, train_sample
from conesight_train.detector.data import (
    TOY_BODY_RGB,
    LabelledFrame,
    RendererFrames,
    ToyFrames,
    read_json_labels,
    vehicle_from_camera_rotation,
)
from conesight_train.detector.frame_input import (
    FILL,
    FrameInputParams,
    boxes_to_frame,
    frame_to_input,
)
from conesight_train.detector.model import STRIDE_PX, decode_boxes, peak_scores
from conesight_train.detector.postprocess import Thresholds, decode
from conesight_train.detector.targets import encode

SMALL_INPUT = FrameInputParams(input_width_px=128, input_height_px=96)


def test_a_1920x1200_frame_is_the_exact_2x2_block_mean_with_fill_below():
    rng = np.random.default_rng(0)
    frame = rng.integers(0, 256, (120, 192, 3), dtype=np.uint8)
    params = FrameInputParams(input_width_px=96, input_height_px=64)
    x, scale = frame_to_input(frame, params)
    assert scale == (0.5, 0.5) and x.shape == (3, 64, 96)
    ref = frame.astype(np.float64).reshape(60, 2, 96, 2, 3).mean(axis=(1, 3))
    np.testing.assert_allclose(x[:, :60], np.floor(ref + 0.5).transpose(2, 0, 1), atol=1e-4)
    assert (x[:, 60:] == FILL).all()


@pytest.mark.parametrize("hw", [(720, 1280), (1038, 1280), (410, 1280), (2000, 300), (50, 60)])
def test_any_frame_fits_the_input_and_boxes_map_back(hw):
    params = FrameInputParams()
    frame = np.zeros((*hw, 3), np.uint8)
    x, (sx, sy) = frame_to_input(frame, params)
    assert x.shape == (3, 608, 960)
    rw, rh = params.resized_wh(hw)
    assert rw == 960 or rh == 608
    assert abs(sx - sy) < 0.01
    boxes = np.array([[10.0, 20.0, 30.0, 45.0]])
    there = boxes * [sx, sy, sx, sy]
    np.testing.assert_allclose(boxes_to_frame(there, (sx, sy)), boxes, atol=1e-9)


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


def test_training_crops_keep_boxes_on_the_cones():
    frames = ToyFrames(40, seed=3, cones_per_frame=6)
    params = DetectorAugmentParams(
        crop_width_px=128,
        crop_height_px=96,
        p_hsv=0.0,
        photometric=DetectorAugmentParams().photometric.__class__(
            p_colour=0, p_gamma=0, p_blur=0, p_noise=0, p_jpeg=0
        ),
    )
    checked = 0
    for i in range(len(frames)):
        for seed in range(4):
            sample = train_sample(frames[i], SMALL_INPUT, np.random.default_rng(seed), params)
            assert sample.image.shape == (3, 96, 128)
            img = sample.image.transpose(1, 2, 0)
            for box, cls in zip(sample.boxes_px, sample.classes, strict=True):
                h = box[3] - box[1]
                if h < 14 or box[3] >= 95 or box[1] <= 1 or box[0] <= 1 or box[2] >= 127:
                    continue  # small or clipped: the sampled pixel may be an edge
                x, y = int((box[0] + box[2]) / 2), int(box[3] - 0.15 * h)
                assert np.abs(img[y, x] - np.array(TOY_BODY_RGB[cls])).max() < 40, (i, seed, box)
                checked += 1
    assert checked > 10


def test_inference_input_keeps_boxes_on_the_cones():
    checked = 0
    frames = ToyFrames(20, seed=4, cones_per_frame=6)
    for i in range(len(frames)):
        sample = to_input(frames[i], SMALL_INPUT)
        img = sample.image.transpose(1, 2, 0)
        for box, cls in zip(sample.boxes_px, sample.classes, strict=True):
            h = box[3] - box[1]
            if h < 10 or box[0] <= 1 or box[2] >= 127:
                continue
            x, y = int((box[0] + box[2]) / 2), int(box[3] - 0.15 * h)
            assert np.abs(img[y, x] - np.array(TOY_BODY_RGB[cls])).max() < 40, box
            checked += 1
    assert checked >= 5


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


def test_extrinsics_forms_agree(tmp_path):
    # The horizon (the image of the vehicle's forward axis) of a camera pitched down by 0.1
    # rad, from each extrinsics form the renderer and conesight-core write.
    pitch = 0.1
    want = 600.0 - 2000.0 * np.tan(pitch)
    level = np.array([[0.0, 0.0, 1.0], [-1.0, 0.0, 0.0], [0.0, -1.0, 0.0]])
    c, s = np.cos(pitch), np.sin(pitch)
    about_y = np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    poses = [
        {"rotation_xyzw": [float(v) for v in quaternion_xyzw(about_y @ level)]},
        {"rotation": {"quaternion_xyzw": [0.0, np.sin(pitch / 2), 0.0, np.cos(pitch / 2)]}},
        {"rotation": {"rpy_rad": [0.0, pitch, 0.0]}},
        {"height_m": 1.0, "pitch_down_rad": pitch},
    ]
    for pose in poses:
        forward = vehicle_from_camera_rotation(pose).T @ np.array([1.0, 0.0, 0.0])
        assert 600.0 + 2000.0 * forward[1] / forward[2] == pytest.approx(want, abs=1e-6), pose
