"""Issue 38's data: the onboard-video degradation (sizes, boxes, the car's body, determinism,
the YOLO copy read back), hard negatives (what counts as one, windows centred on them, a
clear error for a missing file) and the training's `--device`."""

import json
from dataclasses import replace

import numpy as np
import pytest

from conesight_train.detector.augment import DetectorAugmentParams, train_sample
from conesight_train.detector.config import TrainConfig, open_source
from conesight_train.detector.data import LabelledFrame, ToyFrames
from conesight_train.detector.degrade import DegradeParams, degrade, write_degraded_split
from conesight_train.detector.frame_input import FrameInputParams
from conesight_train.detector.negatives import hard_negatives, is_negative, merge
from conesight_train.detector.train import train


def frame(h: int = 1200, w: int = 1920) -> LabelledFrame:
    """A grey frame with a cone high up and one at the bottom centre, under any car nose."""
    image = np.full((h, w, 3), 120, np.uint8)
    boxes = np.array([[100, 300, 140, 360], [w / 2 - 30, h - 60, w / 2 + 30, h - 5]], np.float32)
    return LabelledFrame(image, boxes, np.array([0, 1]), np.array([np.nan, np.nan]), "f")


def test_degrade_scales_to_640_rows_with_its_boxes_and_is_seeded():
    f = frame()
    d = degrade(f, np.random.default_rng(1), DegradeParams(p_ego=0.0))
    assert d.image_rgb.shape == (640, 1024, 3)
    np.testing.assert_allclose(d.boxes_px, f.boxes_px * (640 / 1200), rtol=1e-5)
    assert list(d.classes) == [0, 1] and not d.difficult_mask().any()
    again = degrade(f, np.random.default_rng(1), DegradeParams(p_ego=0.0))
    np.testing.assert_array_equal(d.image_rgb, again.image_rgb)
    other = degrade(f, np.random.default_rng(2), DegradeParams(p_ego=0.0))
    assert np.abs(d.image_rgb.astype(int) - other.image_rgb).mean() > 1.0
    # A small frame is not enlarged.
    small = degrade(frame(480, 640), np.random.default_rng(1), DegradeParams(p_ego=0.0))
    assert small.image_rgb.shape == (480, 640, 3)


def test_the_cars_body_hides_the_cone_in_front_of_it_and_not_the_far_one():
    hidden = 0
    for seed in range(10):
        d = degrade(frame(), np.random.default_rng(seed), DegradeParams(p_ego=1.0))
        assert d.classes[0] == 0 and not d.difficult_mask()[0]
        if d.classes[1] == -1:
            assert d.difficult_mask()[1]
            hidden += 1
        # The body is drawn: the bottom centre is no longer the frame's grey.
        bottom = d.image_rgb[-5:, 500:524].astype(int)
        assert np.abs(bottom - 120).mean() > 10
    assert hidden >= 5, f"the bottom cone was hidden in {hidden} of 10 frames"


def test_the_degraded_copy_reads_back_as_a_yolo_split(tmp_path):
    count = write_degraded_split("toy:3:4", tmp_path / "deg", 38, DegradeParams(rows=96))
    assert count == 3
    copy = open_source(f"yolo:{tmp_path / 'deg'}")
    toys = ToyFrames(3, 4)
    assert len(copy) == 3
    for i in range(3):
        got, want = copy[i], toys[i]
        assert got.image_rgb.shape[0] == 96
        (gh, gw), (wh, ww) = got.image_rgb.shape[:2], want.image_rgb.shape[:2]
        k = np.array([gw / ww, gh / wh, gw / ww, gh / wh])
        kept = got.classes >= 0
        # Every cone is there, scaled; those the car's body hides are ignore regions.
        assert len(got.classes) == len(want.classes)
        np.testing.assert_allclose(got.boxes_px[kept], want.boxes_px[kept] * k, atol=0.05)
        assert (got.classes[kept] == want.classes[kept]).all()


def test_a_negative_is_a_box_on_no_label():
    truths = np.array([[0, 0, 10, 20], [100, 100, 110, 120]], float)
    assert is_negative(np.array([50, 50, 60, 70.0]), truths)
    assert not is_negative(np.array([1, 1, 11, 21.0]), truths)  # on a cone
    assert not is_negative(np.array([101, 105, 106, 115.0]), truths)  # part of a cone
    assert is_negative(np.array([50, 50, 60, 70.0]), np.zeros((0, 4)))


def test_windows_centre_on_the_mined_negatives(tmp_path):
    path = tmp_path / "negatives.json"
    f = frame()
    f.image_rgb[200:260, 1500:1540] = (0, 0, 255)  # the "sign" the model took for a cone
    path.write_text(json.dumps({"f": [[1500, 200, 1540, 260, 0.8]]}))
    params = DetectorAugmentParams(
        hard_negatives=str(path), p_on_negative=1.0, p_hsv=0.0, p_flip=0.0, scale_range=(1, 1)
    )
    for seed in range(5):
        sample = train_sample(f, FrameInputParams(1152, 736), np.random.default_rng(seed), params)
        r, b = sample.image[0], sample.image[2]
        assert ((b - r) > 100).sum() > 50, f"seed {seed}: the window missed the negative"
    with pytest.raises(ValueError, match="negatives"):
        hard_negatives(str(tmp_path / "missing.json"))


def test_negatives_of_several_sources_merge_and_a_shared_frame_name_is_an_error():
    found: dict[str, list] = {}
    merge(found, {"amz_001": [[1, 2, 3, 4, 0.5]]}, "yolo:train")
    merge(found, {"000000": [[5, 6, 7, 8, 0.9]]}, "out/sim-cone-free")
    assert sorted(found) == ["000000", "amz_001"]
    with pytest.raises(ValueError, match="out/sim-b: frame names \\['000000'\\]"):
        merge(found, {"000000": [[0, 0, 1, 1, 0.4]]}, "out/sim-b")
    assert found["000000"] == [[5, 6, 7, 8, 0.9]]


def test_training_on_a_missing_gpu_says_so(tmp_path):
    import torch

    if torch.cuda.is_available():
        pytest.skip("this machine has a GPU")
    config = replace(TrainConfig(), sources=[], out=str(tmp_path), device="cuda")
    with pytest.raises(SystemExit, match="no CUDA GPU"):
        train(config, progress=False)


def test_pasted_large_orange_cones_come_with_their_boxes_and_cover_no_label(tmp_path):
    from conesight_train.detector.paste import LARGE_ORANGE, load_bank, paste_cones

    # A bank of one orange cone on grey road, cut with its margin.
    patch = np.full((60, 40, 3), 90, np.uint8)
    patch[6:54, 4:36] = (240, 110, 20)
    path = tmp_path / "bank.npz"
    np.savez(
        path,
        pixels=patch.reshape(-1),
        shapes=np.array([[60, 40]]),
        boxes=np.array([[4.0, 6.0, 36.0, 54.0]]),
    )
    bank = load_bank(str(path))
    canvas = np.full((384, 640, 3), 120, np.uint8)
    labelled = np.array([[0.0, 0.0, 320.0, 384.0]])  # the left half holds a labelled cone
    for seed in range(5):
        out, pasted = paste_cones(canvas, labelled, bank, np.random.default_rng(seed), 2)
        for x0, y0, x1, y1 in pasted:
            assert x0 >= 320 and 0 <= y0 < y1 <= 384 and x1 <= 640
            centre = out[int((y0 + y1) / 2), int((x0 + x1) / 2)]
            assert centre[0] > 200 and centre[2] < 60, centre  # the cone's orange
        assert (out[:, :320] == 120).all()
    params = DetectorAugmentParams(paste_bank=str(path), p_paste=1.0, p_on_cone=0.0)
    sample = train_sample(frame(), FrameInputParams(1152, 736), np.random.default_rng(3), params)
    assert (sample.classes == LARGE_ORANGE).sum() >= 1
