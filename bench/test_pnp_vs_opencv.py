"""Checks of the benchmark's statistics and verdicts (no OpenCV or Rust binary needed)."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

# The script is not a package; make it importable under any pytest import mode.
sys.path.insert(0, str(Path(__file__).resolve().parent))
import pnp_vs_opencv as bench


def test_failures_count_as_infinite_error() -> None:
    errors = bench.relative_errors(np.array([10.5, np.nan, 19.0]), np.array([10.0, 5.0, 20.0]))
    assert np.allclose(errors[[0, 2]], [0.05, 0.05])
    assert np.isinf(errors[1])
    median, p90, _, failures = bench.stats(errors, np.array([1.0, 1.0, 1.0]))
    assert failures == 1
    assert median == 0.05
    assert np.isinf(p90)


def test_bands_partition_the_ranges() -> None:
    true_m = np.array([2.0, 4.99, 5.0, 12.0, 19.9, 29.9])
    masks = bench.band_masks(true_m)
    per_band = sum(mask.astype(int) for name, mask in masks if name != "all")
    assert np.all(per_band == 1)
    assert masks[-1][0] == "all" and masks[-1][1].all()


def _results(
    ours_error: float, opencv_error: float, ours_us: float, opencv_us: float
) -> tuple[np.ndarray, dict[str, bench.MethodResult]]:
    true_m = np.array([3.0, 7.0, 12.0, 17.0, 25.0])

    def make(error: float, us: float) -> bench.MethodResult:
        return bench.MethodResult(true_m * (1 + error), np.full(5, us))

    results = {bench.OURS: make(ours_error, ours_us), bench.OURS_GROUND: make(ours_error, ours_us)}
    for method in bench.OPENCV_METHODS:
        results[method] = make(opencv_error, opencv_us)
    return true_m, results


def test_verdicts_pass_and_fail_on_the_numbers() -> None:
    true_m, good = _results(0.01, 0.02, 1.0, 50.0)
    _, summary_good = bench.table("t", true_m, good)
    _, bad = _results(0.03, 0.02, 10.0, 50.0)
    _, summary_bad = bench.table("t", true_m, bad)
    passing = "\n".join(bench.verdicts(summary_good, summary_good))
    assert "FAIL" not in passing and passing.count("PASS") > 10
    failing = "\n".join(bench.verdicts(summary_good, summary_bad))
    # Outlier run worse than OpenCV and 3x the clean error; and 5x, not 20x, faster.
    assert "median / clean median = 3.00" in failing
    assert "5.0x (target >= 20x): FAIL" in failing
