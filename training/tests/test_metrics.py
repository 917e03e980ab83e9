"""Error summaries, including whether sigma_px is usable as a weight."""

import numpy as np
import pytest

from conesight_train.metrics import KeypointErrors, rank_correlation


def test_sigma_summary_detects_informative_and_useless_sigmas():
    rng = np.random.default_rng(0)
    sigma = rng.uniform(0.2, 3.0, size=(500, 7))
    errors = rng.laplace(0.0, sigma)  # |e| has mean sigma under a Laplace law
    errors = np.abs(errors)
    good = KeypointErrors(errors, sigma).summary()
    assert good["sigma_error_rank_correlation"] > 0.3
    assert good["error_over_sigma_mean"] == pytest.approx(1.0, abs=0.1)
    shuffled = KeypointErrors(errors, rng.permutation(sigma.ravel()).reshape(sigma.shape))
    assert abs(shuffled.summary()["sigma_error_rank_correlation"]) < 0.1
    assert "sigma_mean_px" not in KeypointErrors(errors).summary()


def test_rank_correlation_extremes():
    a = np.arange(10.0)
    assert rank_correlation(a, a**3) == pytest.approx(1.0)
    assert rank_correlation(a, -a) == pytest.approx(-1.0)
