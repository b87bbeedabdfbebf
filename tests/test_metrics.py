"""drpt.metrics on small hand-made arrays with values worked out by hand."""

from __future__ import annotations

import numpy as np
import pytest

from drpt import metrics

# Two pixels of two channels: differences 0, 1, 0, 2; one 0/0 term.
X = np.array([1.0, 2.0, 0.0, 3.0]).reshape(1, 2, 2)
REF = np.array([1.0, 1.0, 0.0, 1.0]).reshape(1, 2, 2)


def test_rel_mse_known_value():
    # (0 + 1/1.01 + 0 + 4/1.01) / 4
    assert metrics.rel_mse(X, REF) == pytest.approx(5.0 / 1.01 / 4.0, rel=1e-12)
    assert metrics.rel_mse(X, REF, eps=0.0 + 1.0) == pytest.approx((0.5 + 2.0) / 4.0)


def test_mae_known_value():
    assert metrics.mae(X, REF) == pytest.approx(0.75)


def test_smape_known_value_and_zero_over_zero():
    # terms: 0, 2*1/3, 0 (0/0 := 0), 2*2/4
    assert metrics.smape(X, REF) == pytest.approx((2.0 / 3.0 + 1.0) / 4.0, rel=1e-12)
    z = np.zeros((2, 2, 3))
    assert metrics.smape(z, z) == 0.0
    assert np.isfinite(metrics.smape(z, z))
    # one side zero: the term is its maximum, 2
    assert metrics.smape(np.ones((1, 1, 1)), np.zeros((1, 1, 1))) == pytest.approx(2.0)


def test_error_map_known_values():
    e = metrics.error_map(X, REF)
    assert e.shape == (1, 2)
    # pixel 0: (0/1.01 + 1/1.01)/2, pixel 1: (0/0.01 + 2/1.01)/2
    np.testing.assert_allclose(e, [[0.5 / 1.01, 1.0 / 1.01]], rtol=1e-12)


def test_outside_ci_known_values():
    x = np.array([0.0, 1.0, 2.0, 3.0]).reshape(1, 4, 1)
    ref = np.zeros_like(x)
    var = np.ones_like(x)
    # threshold 1.5: values 2 and 3 are outside
    assert metrics.outside_ci(x, var, ref, z=1.5) == pytest.approx(0.5)
    # var_ref widens the interval of the third value to 1.5 * 2 = 3 (2 is inside, 3 > 1.5)
    var_ref = np.array([0.0, 0.0, 3.0, 0.0]).reshape(1, 4, 1)
    assert metrics.outside_ci(x, var, ref, var_ref, z=1.5) == pytest.approx(0.25)
    # exactly on the boundary counts as inside (strict >)
    assert metrics.outside_ci(np.full((1, 1, 1), 3.0), np.ones((1, 1, 1)),
                              np.zeros((1, 1, 1)), z=3.0) == 0.0


def test_outside_ci_zero_variance():
    x = np.array([1.0, 2.0, 5.0, 0.0]).reshape(2, 2, 1)
    ref = np.array([1.0, 3.0, 5.0, 0.0]).reshape(2, 2, 1)
    # zero variance: equal values inside, the one unequal value outside
    assert metrics.outside_ci(x, np.zeros_like(x), ref) == pytest.approx(0.25)


def test_identical_images_give_zeros():
    rng = np.random.default_rng(1)
    img = rng.random((5, 7, 3))
    s = metrics.summary(img, img.copy(), np.full_like(img, 1e-3), np.zeros_like(img))
    for k in ("rel_mse", "mae", "smape", "outside_ci", "mean_rel_error", "max_rel_error"):
        assert s[k] == 0.0, k
    assert metrics.summary(img, img)["outside_ci"] is None  # no variance, no interval


def test_outside_ci_gaussian_noise_matches_997_interval():
    # Unbiased Gaussian estimates with the stated variances: 2(1 - Phi(3)) = 0.270%.
    # n = 1e6 values: binomial sd = 5.2e-5, so a 3e-4 bound is ~6 sd.
    rng = np.random.default_rng(2024)
    shape = (500, 500, 4)
    sigma = 0.1
    ref_true = rng.random(shape)
    x = ref_true + sigma * np.sqrt(0.5) * rng.standard_normal(shape)
    ref = ref_true + sigma * np.sqrt(0.5) * rng.standard_normal(shape)
    var = np.full(shape, sigma * sigma / 2)
    f = metrics.outside_ci(x, var, ref, var, z=3.0)
    assert abs(f - 0.0027) < 3e-4, f
    # exact reference
    f1 = metrics.outside_ci(ref_true + sigma * rng.standard_normal(shape),
                            np.full(shape, sigma ** 2), ref_true)
    assert abs(f1 - 0.0027) < 3e-4, f1
    # a bias of one sigma is caught: 1 - Phi(2) + Phi(-4) = 2.28%
    f2 = metrics.outside_ci(x + sigma, var, ref, var, z=3.0)
    assert 0.02 < f2 < 0.026, f2


def test_shape_mismatch_raises():
    with pytest.raises(ValueError):
        metrics.mae(np.zeros((2, 2, 3)), np.zeros((2, 3, 3)))
