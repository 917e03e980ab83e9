"""The shipped keypoint network on the real validation crops (split by source frame, never
trained on): issue 13's targets on all of them, and issue 37's 1.5 px mean on each source
(AMZ's two sets, TU Wien's). Skipped when ../shared/data is absent."""

from pathlib import Path

import numpy as np
import pytest

from conesight_train.eval_keypoints import evaluate, predictor_for
from conesight_train.train_keypoints import open_sources

REPO = Path(__file__).resolve().parents[2]
SHARED = REPO.parent / "shared" / "data"
VAL_SPECS = [
    f"real:{SHARED / 'real-dev' / 'fsoco-keypoint-crops'}:val",
    f"real:{SHARED / 'real-train' / 'amz-keypoint-crops-hires'}:val",
    f"real:{SHARED / 'real-train' / 'tuwr-keypoint-crops'}:val",
]


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data is absent")
def test_real_validation_error_and_sigma_calibration():
    errors = evaluate(predictor_for(REPO / "models" / "keypoints.onnx"), open_sources(VAL_SPECS))
    summary = errors.summary()
    assert summary["count"] > 300
    assert summary["mean_px"] <= 2.0, summary["mean_px"]
    per_keypoint = summary["per_keypoint_mean_px"]
    assert max(per_keypoint.values()) <= 3.0, per_keypoint
    # sigma_px is a per-axis standard deviation: about 68 % of |e_x|, |e_y| within it.
    within = summary["within_1_sigma_per_axis"]
    assert 0.58 <= within <= 0.78, within
    assert np.isfinite(errors.sigma_px).all()


@pytest.mark.skipif(not SHARED.is_dir(), reason="../shared/data is absent")
@pytest.mark.parametrize("spec", VAL_SPECS, ids=["amz", "amz_hires", "tuwr"])
def test_each_real_source_within_one_and_a_half_pixels(spec: str):
    errors = evaluate(predictor_for(REPO / "models" / "keypoints.onnx"), open_sources([spec]))
    summary = errors.summary()
    assert summary["count"] > 80
    assert summary["mean_px"] <= 1.5, summary["mean_px"]
