"""Repeat-factor sampling: rare classes drawn more often, reproducible per epoch, off at t = 0."""

from __future__ import annotations

import numpy as np

from conesight_train.detector.data import ToyFrames
from conesight_train.detector.sampling import (
    class_frame_fractions,
    epoch_order,
    frame_classes,
    repeat_factors,
)


def test_factors_follow_the_lvis_rule() -> None:
    # Class 0 in every frame, class 3 in one frame of ten.
    sets = [np.array([0, 0, 3])] + [np.array([0, 1])] * 9
    fractions = class_frame_fractions(sets, 4)
    np.testing.assert_allclose(fractions, [1.0, 0.9, 0.0, 0.1])
    factors = repeat_factors(sets, 4, threshold=0.4)
    np.testing.assert_allclose(factors[0], np.sqrt(0.4 / 0.1))
    np.testing.assert_allclose(factors[1:], 1.0)
    assert np.all(repeat_factors(sets, 4, threshold=0.0) == 1.0)


def test_rare_frames_are_drawn_more_often_and_orders_replay() -> None:
    factors = np.array([4.0] + [1.0] * 99)
    orders = [epoch_order(factors, seed=3, epoch=e) for e in range(50)]
    share = np.mean([order.count(0) / len(order) for order in orders])
    assert 0.025 < share < 0.055  # expected 4 / 103 = 0.039, uniform would be 0.01
    assert epoch_order(factors, seed=3, epoch=7) == orders[7]
    assert epoch_order(factors, seed=3, epoch=8) != orders[7]


def test_plain_permutation_when_off() -> None:
    order = epoch_order(np.ones(20), seed=0, epoch=0)
    assert sorted(order) == list(range(20))


def test_frame_classes_without_a_reader_decode_the_frame() -> None:
    toy = ToyFrames(2, seed=0)
    assert list(frame_classes(toy, 1)) == list(toy[1].classes)
