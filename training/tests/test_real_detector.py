"""The shipped detector on real frames it never trained on (`fsoco-boxes/test`; skipped when
../shared is absent): any camera pitch, no calibration given.

A test frame moved up or down by 25 % of its height (what a camera pitched by that much would
see; the uncovered rows grey) keeps at least 90 % of the recall it has unmoved, on the cones that
stay in the frame, at the card's operating threshold.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from conesight_train.detector.evaluate import onnx_runner, run_frames, shift_frame
from conesight_train.detector.metrics import evaluate
from conesight_train.detector.model import CLASS_NAMES

ROOT = Path(__file__).resolve().parents[2]
TEST_SPLIT = ROOT.parent / "shared/data/real-train/fsoco-boxes/test"
MODEL = ROOT / "models/detector.onnx"
FRAMES = 40  # every third test frame: both teams, a minute of CPU
SHIFT = 0.25
KEPT_RECALL = 0.9


@pytest.fixture(scope="module")
def detector_and_frames():
    if not TEST_SPLIT.is_dir():
        pytest.skip(f"{TEST_SPLIT}: real test frames absent")
    from conesight_train.detector.real_frames import YoloFrames

    frames = YoloFrames(TEST_SPLIT)
    picked = [frames[i] for i in range(0, len(frames), max(1, len(frames) // FRAMES))][:FRAMES]
    return onnx_runner(MODEL, 2), picked


def recall(detector, frames, shift: float) -> tuple[float, int]:
    runner, params, thresholds = detector
    moved = [shift_frame(f, shift) for f in frames] if shift else frames
    results = run_frames(moved, runner, params, thresholds, None, 0)
    metrics = evaluate(results, CLASS_NAMES, thresholds.score_threshold, max_range_m=None)
    truths = sum(int(np.sum(f.classes >= 0)) for f in moved)
    return float(metrics["recall"]), truths


@pytest.mark.parametrize("shift", [SHIFT, -SHIFT])
def test_a_pitched_view_keeps_its_recall_without_calibration(detector_and_frames, shift):
    detector, frames = detector_and_frames
    base, base_truths = recall(detector, frames, 0.0)
    moved, moved_truths = recall(detector, frames, shift)
    print(f"recall unmoved {base:.3f} ({base_truths} cones), moved {shift:+g}: {moved:.3f} "
          f"({moved_truths} cones)")  # fmt: skip
    assert moved_truths > 0.5 * base_truths
    assert base > 0.5
    assert moved >= KEPT_RECALL * base
