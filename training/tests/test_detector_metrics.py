"""Detection metrics and NMS on hand-made cases."""

import numpy as np
import pytest

from conesight_train.detector.metrics import (
    ImageResult,
    average_precision,
    box_residuals,
    evaluate,
)
from conesight_train.detector.postprocess import Thresholds, decode

NAMES = ("blue", "yellow", "orange", "large_orange")


def image(dets, truths, classes, ranges=None):
    truths = np.array(truths, float).reshape(-1, 4)
    return ImageResult(
        np.array(dets, float).reshape(-1, 6),
        truths,
        np.array(classes, int),
        np.full(len(truths), np.nan) if ranges is None else np.array(ranges, float),
    )


def test_perfect_detections_score_one():
    img = image(
        [[0, 0, 10, 20, 0.9, 0], [50, 0, 60, 20, 0.8, 1]], [[0, 0, 10, 20], [50, 0, 60, 20]], [0, 1]
    )
    m = evaluate([img], NAMES, 0.5)
    assert m["map50"] == 1.0 and m["precision"] == 1.0 and m["recall"] == 1.0
    assert np.isnan(m["per_class"]["orange"]["ap50"])  # no truths: not in the mean


def test_ap_by_hand():
    # Scores: TP 0.9, FP 0.8, TP 0.7; 3 truths. Precision envelope: 1 up to R=1/3, 2/3 up to 2/3.
    hits = np.array([True, False, True])
    ap = average_precision(np.array([0.9, 0.8, 0.7]), hits, 3)
    assert ap == pytest.approx(1 / 3 * 1.0 + 1 / 3 * 2 / 3)


def test_wrong_class_and_duplicates_are_false_positives():
    truths = [[0, 0, 10, 20]]
    dets = [[0, 0, 10, 20, 0.9, 1], [0, 0, 10, 20, 0.8, 0], [1, 0, 10, 20, 0.7, 0]]
    m = evaluate([image(dets, truths, [0])], NAMES, 0.5)
    assert m["precision"] == pytest.approx(1 / 3) and m["recall"] == 1.0
    assert m["per_class"]["blue"]["ap50"] == 1.0  # the best-scored blue is the hit


def test_iou_threshold_and_ranges():
    truths = [[0, 0, 10, 20], [100, 0, 104, 10]]
    # The second detection overlaps its truth with IoU 0.4 < 0.5: a miss and a false positive.
    dets = [[0, 0, 10, 20, 0.9, 0], [100, 0, 104, 4, 0.9, 0]]
    m = evaluate([image(dets, truths, [0, 0], [5.0, 25.0])], NAMES, 0.5)
    assert m["recall"] == 0.5
    assert m["recall_by_range"]["0-10 m"] == {"truths": 1, "recall": 1.0}
    assert m["recall_by_range"]["20-30 m"] == {"truths": 1, "recall": 0.0}
    assert m["recall_within_20m"] == 1.0


def test_below_threshold_counts_for_ap_not_for_recall():
    m = evaluate([image([[0, 0, 10, 20, 0.2, 0]], [[0, 0, 10, 20]], [0])], NAMES, 0.5)
    assert m["map50"] == 1.0 and m["recall"] == 0.0


def test_class_aware_nms():
    # Columns: cx, cy, w, h, then 4 class scores.
    out = np.array(
        [
            [10, 10, 10, 20, 0.9, 0, 0, 0],
            [11, 10, 10, 20, 0.8, 0, 0, 0],  # same class, IoU 0.82: suppressed
            [11, 10, 10, 20, 0, 0.7, 0, 0],  # other class: kept
            [40, 10, 10, 20, 0.6, 0, 0, 0],  # far: kept
            [80, 10, 10, 20, 0.1, 0, 0, 0],  # below threshold
        ],
        float,
    ).T
    dets = decode(out, Thresholds(score_threshold=0.3, nms_iou=0.5))
    assert dets[:, 4].tolist() == pytest.approx([0.9, 0.7, 0.6])
    assert dets[:, 5].tolist() == [0, 1, 0]
    np.testing.assert_allclose(dets[0, :4], [5, 0, 15, 20])
    assert len(decode(out, Thresholds(score_threshold=0.3, max_detections=2))) == 2


def test_difficult_truths_count_nowhere():
    truths = np.array([[0, 0, 10, 20], [50, 0, 52, 3]], float)
    dets = np.array([[0, 0, 10, 20, 0.9, 0], [50, 0, 52, 3, 0.8, 0]], float)
    hard = np.array([False, True])
    img = ImageResult(dets, truths, np.array([0, 0]), np.array([5.0, 5.0]), hard)
    m = evaluate([img], NAMES, 0.5)
    assert m["precision"] == 1.0 and m["recall"] == 1.0
    assert m["per_class"]["blue"]["truths"] == 1
    # Missing the difficult cone costs nothing either.
    img = ImageResult(dets[:1], truths, np.array([0, 0]), np.array([5.0, 5.0]), hard)
    assert evaluate([img], NAMES, 0.5)["recall_by_range"]["0-10 m"]["truths"] == 1


def test_cones_beyond_the_working_range_count_only_in_their_band():
    truths = [[0, 0, 10, 20], [100, 0, 104, 10], [200, 0, 204, 10]]
    # The near cone is found, the 45 m cone is missed, the 40 m cone is found.
    dets = [[0, 0, 10, 20, 0.9, 0], [200, 0, 204, 10, 0.9, 0]]
    img = image(dets, truths, [0, 0, 0], [5.0, 45.0, 40.0])
    m = evaluate([img], NAMES, 0.5, max_range_m=30.0)
    assert m["recall"] == 1.0 and m["precision"] == 1.0 and m["map50"] == 1.0
    assert m["per_class"]["blue"]["truths"] == 1
    assert m["recall_by_range"][">= 30 m"] == {"truths": 2, "recall": 0.5}
    everything = evaluate([img], NAMES, 0.5, max_range_m=None)
    assert everything["recall"] == pytest.approx(2 / 3)
    assert everything["per_class"]["blue"]["truths"] == 3


def test_a_loose_box_on_an_ignored_cone_is_not_a_false_positive():
    truths = [[0, 0, 10, 20], [100, 0, 104, 10]]  # a 5 m cone and a 45 m one
    # The far cone's detection is loose (IoU 0.4 < 0.5) but lies wholly on it: ignored.
    dets = [[0, 0, 10, 20, 0.9, 0], [100, 0, 104, 4, 0.9, 0], [300, 0, 304, 10, 0.9, 0]]
    m = evaluate([image(dets, truths, [0, 0], [5.0, 45.0])], NAMES, 0.5)
    assert m["precision"] == pytest.approx(1 / 2)  # the hit and the background box
    assert m["recall"] == 1.0


def test_unmatched_detections_standing_beyond_the_working_range_count_nowhere():
    truths = [[0, 0, 10, 20], [100, 0, 104, 10]]  # a 5 m cone and a 45 m one
    # A loose box next to the far cone (neither IoU 0.5 nor mostly on it), and a near miss.
    dets = [[0, 0, 10, 20, 0.9, 0], [101, 2, 107, 14, 0.9, 0], [300, 0, 304, 10, 0.9, 0]]
    base = image(dets, truths, [0, 0], [5.0, 45.0])
    without_ranges = evaluate([base], NAMES, 0.5)
    assert without_ranges["precision"] == pytest.approx(1 / 3)
    ranged = ImageResult(
        base.detections,
        base.truth_boxes,
        base.truth_classes,
        base.truth_range_m,
        detection_range_m=np.array([5.0, 44.0, 12.0]),
    )
    m = evaluate([ranged], NAMES, 0.5)
    assert m["precision"] == pytest.approx(1 / 2)  # the far loose box is left out, not the 12 m one
    # A detection matched to an in-range truth stays a hit whatever its own range says.
    matched = ImageResult(
        base.detections[:1],
        base.truth_boxes,
        base.truth_classes,
        base.truth_range_m,
        detection_range_m=np.array([31.0]),
    )
    assert evaluate([matched], NAMES, 0.5)["precision"] == 1.0
    # With no working range nothing is left out.
    assert evaluate([ranged], NAMES, 0.5, max_range_m=None)["precision"] == pytest.approx(1 / 3)


def test_box_residuals_find_a_lean_by_height_band():
    # Small cones (10 px detections): truths 1 px lower and 10 % taller than the boxes; large
    # ones (50 px): exact. A low-score box and a wrong-class box take no part.
    small = image(
        [[0, 0, 7, 10, 0.9, 0], [20, 0, 27, 10, 0.8, 1], [40, 0, 47, 10, 0.1, 0]],
        [[0, 0.5, 7, 11.5], [20, 0.5, 27, 11.5], [40, 5, 47, 15]],
        [0, 1, 0],
    )
    large = image([[0, 0, 35, 50, 0.9, 2]], [[0, 0, 35, 50]], [2])
    wrong = image([[0, 0, 7, 10, 0.9, 1]], [[0, 0, 7, 10]], [0])
    rows = box_residuals([small, large, wrong], score_threshold=0.4)
    low = rows["0-20 px"]
    assert low["pairs"] == 2
    assert low["centre_y_over_h_mean"] == pytest.approx(0.1)
    assert low["centre_x_over_h_mean"] == pytest.approx(0.0)
    assert low["log_h_mean"] == pytest.approx(np.log(1.1))
    assert low["log_w_mean"] == pytest.approx(0.0) and low["log_h_sd"] == pytest.approx(0.0)
    assert low["share_under_iou_0.5"] == 0.0
    high = rows[">= 40 px"]
    assert high["pairs"] == 1 and high["log_h_mean"] == pytest.approx(0.0)
    assert rows["20-40 px"]["pairs"] == 0 and np.isnan(rows["20-40 px"]["log_h_mean"])
