"""The evaluation report's numbers and the CI regression check (conesight_train.report)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from conesight_train.report import markdown, metrics


def record(seed, index, range_m, error_m, variant="cone", kp_error_px=None):
    truth = [0.0, 0.0, range_m]
    keypoints = [[10.0 * k, 20.0] for k in range(7)]
    predicted = None
    if kp_error_px is not None:
        predicted = [[x + kp_error_px * 2.0, y] for x, y in keypoints]
    return {
        "seed": seed,
        "index": index,
        "model": "production",
        "class": "blue",
        "range_m": range_m,
        "position_true_m": truth,
        "keypoints_true_px": keypoints,
        "keypoints_px": predicted,
        "image_px_per_patch_px": 2.0,
        "estimates": {
            variant: {
                "position_m": None if error_m is None else [error_m, 0.0, range_m],
                "error": None if error_m is not None else "failed",
                "micros": 3.0,
            }
        },
    }


def test_bands_count_failures_and_percent_of_range():
    records = [record(100, 0, 6.0, 0.06), record(100, 0, 8.0, 0.16), record(100, 1, 9.0, None)]
    rows = metrics.band_rows(*metrics.position_errors(records, "cone"))
    band = next(r for r in rows if r["band"] == "5-10 m")
    assert band["count"] == 3
    assert band["failures"] == 1
    assert band["median_m"] == pytest.approx(0.11)
    assert band["median_percent_of_range"] == pytest.approx(1.5)
    assert rows[-1]["band"] == "all"
    assert "5-10 m" in markdown.band_table(rows)


def test_quadratic_fit_recovers_a_parabola():
    x = np.linspace(2.0, 30.0, 50)
    fit = metrics.quadratic_fit(x, 0.001 * x**2 + 0.01 * x)
    assert metrics.fit_at(fit, 10.0) == pytest.approx(0.2)
    assert metrics.quadratic_fit(x[:2], x[:2]) is None


def test_perturbation_variance_uses_depth_over_solved_draws():
    records = [
        {"range_m": 15.0, "level": 0.2, "positions_m": [[0, 0, 14.0], [0, 0, 16.0], None]},
        {"range_m": 5.0, "level": 0.2, "positions_m": [[0, 0, 5.0], None]},  # one draw: skipped
    ]
    variance = metrics.perturbation_variance(records)
    ranges, values = variance[0.2]
    assert list(ranges) == [15.0]
    assert values[0] == pytest.approx(2.0)


def test_check_subset_metrics_and_tolerances():
    records = [record(100, i, 5.0 + i, 0.05 * (i + 1), kp_error_px=0.5) for i in range(6)]
    records.append(record(101, 0, 5.0, 9.0, kp_error_px=0.5))
    subset = metrics.check_subset(records, [100], 4)
    assert len(subset) == 4
    current = metrics.check_metrics(subset, ["cone"])
    assert current["cones"] == 4
    assert current["keypoint_mean_patch_px"] == pytest.approx(0.5)
    assert current["cone.failures"] == 0
    committed = json.loads(json.dumps(current))
    assert all(ok for *_, ok in metrics.compare(current, committed))
    # Median 0.125 m: 30 % worse is outside 0.01 m + 5 %, 2 % worse is inside.
    for factor, expected in ((1.30, False), (1.02, True)):
        worse = dict(current, **{"cone.median_m": current["cone.median_m"] * factor})
        row = next(r for r in metrics.compare(worse, committed) if r[0] == "cone.median_m")
        assert row[4] is expected, factor
    # One cone more, or a metric gone, fails.
    assert not all(ok for *_, ok in metrics.compare(dict(current, cones=5.0), committed))
    assert not all(
        ok for *_, ok in metrics.compare(dict(current, **{"cone.p90_m": None}), committed)
    )
