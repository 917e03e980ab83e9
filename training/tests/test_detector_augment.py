"""Detector augmentation: the HSV jitter keeps yellow and orange cones apart (the keypoint
pipeline's per-channel gains did not), and crops are centred on rare classes more often."""

import cv2
import numpy as np

from conesight_train.augment import AugmentParams, photometric
from conesight_train.detector.augment import DetectorAugmentParams, hsv_jitter, train_sample
from conesight_train.detector.data import LabelledFrame
from conesight_train.detector.frame_input import FrameInputParams

# Body colours of real cones in FSOCO frames (sampled by eye from AMZ frames): yellow, orange.
YELLOW_RGB = (228, 196, 52)
ORANGE_RGB = (226, 98, 30)


def _hues(rgb: tuple[int, int, int], jitter, draws: int = 400) -> np.ndarray:
    patch = np.tile(np.array(rgb, np.uint8), (8, 8, 1))
    hues = []
    for seed in range(draws):
        out = jitter(patch, np.random.default_rng(seed))
        hsv = cv2.cvtColor(np.ascontiguousarray(out), cv2.COLOR_RGB2HSV)
        hues.append(float(np.median(hsv[..., 0])))
    return np.array(hues)


def test_hsv_jitter_never_turns_a_yellow_cone_orange():
    gains = DetectorAugmentParams().hsv_gains
    yellow = _hues(YELLOW_RGB, lambda x, rng: hsv_jitter(x, rng, gains))
    orange = _hues(ORANGE_RGB, lambda x, rng: hsv_jitter(x, rng, gains))
    assert yellow.min() > orange.max() + 5, (yellow.min(), orange.max())
    # It does jitter: the hue moves by a few units of OpenCV's 180-step circle, and brightness.
    assert 2 <= np.ptp(yellow) <= 8
    patch = np.tile(np.array(YELLOW_RGB, np.uint8), (4, 4, 1))
    out = hsv_jitter(patch, np.random.default_rng(1), gains)
    assert out.dtype == np.uint8 and out.shape == (4, 4, 3)


def test_per_channel_gains_would_turn_yellow_into_orange():
    """Why the detector does not use the keypoint pipeline's colour augmentation."""
    colour_only = AugmentParams(p_colour=1.0, p_gamma=0, p_blur=0, p_noise=0, p_jpeg=0)
    yellow = _hues(YELLOW_RGB, lambda x, rng: photometric(x, rng, colour_only))
    orange = _hues(ORANGE_RGB, lambda x, rng: photometric(x, rng, colour_only))
    assert yellow.min() < orange.max()


def test_crops_are_centred_on_rare_classes_more_often():
    # Nine blue cones and one large orange, far apart: a small crop holds one cone.
    image = np.full((192, 3840, 3), 90, np.uint8)
    xs = np.arange(10) * 380 + 180
    boxes = np.stack([xs, np.full(10, 80), xs + 20, np.full(10, 120)], 1).astype(np.float64)
    classes = np.array([0] * 9 + [3])
    frame = LabelledFrame(image, boxes, classes, np.full(10, np.nan))
    params = DetectorAugmentParams(
        crop_width_px=128,
        crop_height_px=96,
        scale_range=(1.0, 1.0),
        p_on_cone=1.0,
        p_hsv=0.0,
        photometric=AugmentParams(p_colour=0, p_gamma=0, p_blur=0, p_noise=0, p_jpeg=0),
    )
    full = FrameInputParams(input_width_px=3840, input_height_px=192)
    draws = 600
    large = sum(
        3 in train_sample(frame, full, np.random.default_rng(s), params).classes
        for s in range(draws)
    )
    # Weight 4 against nine of weight 1: 4/13 = 0.31 of the crops (unweighted: 0.1).
    assert 0.24 < large / draws < 0.38, large / draws
