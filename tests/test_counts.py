"""Pile-up and its correction (drawing captures: tests/test_noise.py)."""

from __future__ import annotations

import numpy as np
import pytest

from nlosplan._jax import jax, jnp
from nlosplan.sensor_models import counts as C

pileup_expected = jax.jit(C.pileup_expected)
coates_correction = jax.jit(C.coates_correction)


# ------------------------------------------------------------------- pile-up
def test_pileup_hand_formula_three_bins():
    lam = np.array([0.2, 0.5, 1.3])
    n = 1000.0
    got = np.asarray(pileup_expected(lam, n))
    expected = n * np.array(
        [
            1 - np.exp(-0.2),
            np.exp(-0.2) * (1 - np.exp(-0.5)),
            np.exp(-0.2 - 0.5) * (1 - np.exp(-1.3)),
        ]
    )
    np.testing.assert_allclose(got, expected, rtol=1e-14)
    # total detections: one per iteration with at least one photon
    np.testing.assert_allclose(got.sum(), n * (1 - np.exp(-2.0)), rtol=1e-14)


def test_pileup_low_rate_is_linear():
    lam = np.array([1e-9, 3e-9, 0.0, 2e-9])
    got = np.asarray(pileup_expected(lam, 1e6))
    np.testing.assert_allclose(got, 1e6 * lam, rtol=1e-8)
    assert got[2] == 0.0


def test_pileup_matches_monte_carlo_first_photon_detector():
    rng = np.random.default_rng(2024)
    lam = np.array([0.05, 0.3, 0.0, 0.8, 0.1, 0.6])
    n = 200_000
    photons = rng.poisson(lam, size=(n, lam.size))
    hit = photons > 0
    first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
    mc = np.bincount(first[first >= 0], minlength=lam.size).astype(float)
    expected = np.asarray(pileup_expected(lam, float(n)))
    # binomial standard deviation per bin; 5 sigma
    sd = np.sqrt(expected * (1 - expected / n)) + 1.0
    assert np.all(np.abs(mc - expected) < 5 * sd), (mc, expected)
    assert mc[2] == 0 and expected[2] == 0


def test_pileup_batched_and_negative_rates_clipped():
    lam = np.array([[0.1, 0.2], [-0.5, 0.2]])
    got = np.asarray(pileup_expected(lam, 10.0))
    np.testing.assert_allclose(got[1], [0.0, 10.0 * (1 - np.exp(-0.2))], rtol=1e-14)
    np.testing.assert_allclose(got[0], [10 * (1 - np.exp(-0.1)), 10 * np.exp(-0.1) * (1 - np.exp(-0.2))], rtol=1e-14)


def test_pileup_detection_probability_to_one_first_bin():
    lam = np.array([1e3, 0.5, 2.0, 1e-3])
    n = 550_000.0
    got = np.asarray(pileup_expected(lam, n))
    assert np.all(np.isfinite(got))
    assert got[0] == pytest.approx(n, rel=1e-15)
    np.testing.assert_array_equal(got[1:], 0.0)  # exp(-1000) underflows to exactly 0
    assert got.sum() <= n


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_pileup_follows_dtype_and_is_finite_for_huge_rates(dtype):
    lam = np.array([1e30, 1e30, 0.0], dtype)
    got = pileup_expected(lam, 100.0)
    assert got.dtype == dtype
    np.testing.assert_allclose(np.asarray(got), [100.0, 0.0, 0.0])


@pytest.mark.parametrize(
    "dtype, first, big",
    [
        (np.float64, 0.5, 1e16),
        (np.float32, 0.5, 3e7),
        (np.float32, 0.05, 2e6),
        # realistic: crosstalk 1.4e-4 photons/iteration in bin 0, a bright return in bin 1
        (np.float32, 1.38e-4, 512.0),
    ],
)
def test_pileup_dominant_later_bin_still_shadowed(dtype, first, big):
    """Total detections can never exceed the iterations; bin 1 is shadowed by bin 0.

    ``lam = [first, big]``: bin 1 must hold ``N * exp(-first) * (1 - exp(-big))``.
    The exclusive cumulative sum must not be formed as ``cumsum(lam) - lam``
    (that cancels to 0 when ``lam_j`` dominates its own prefix sum).
    """
    lam = np.array([first, big], dtype)
    n = 1000.0
    got = np.asarray(pileup_expected(lam, n), np.float64)
    assert got.sum() <= n * (1 + 1e-6), got
    np.testing.assert_allclose(got, n * np.array([-np.expm1(-first), np.exp(-first)]), rtol=1e-5)


# --------------------------------------------------------------- correction
def test_coates_inverts_pileup_moderate_rates():
    rng = np.random.default_rng(5)
    for _ in range(20):
        lam = rng.uniform(0, 1, size=32)
        lam *= rng.uniform(0.01, 2.99) / lam.sum()  # < 3 photons per iteration in total
        n = 550_000.0
        back = np.asarray(coates_correction(pileup_expected(lam, n), n))
        np.testing.assert_allclose(back, lam, rtol=1e-9, atol=1e-15)


def test_coates_inverts_pileup_float32():
    lam = np.linspace(0.01, 0.1, 20).astype(np.float32)  # 1.1 per iteration in total
    n = 550_000.0
    back = coates_correction(pileup_expected(lam, n), n)
    assert back.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(back), lam, rtol=2e-3)


def test_coates_hand_values_and_saturated_bins():
    n = 100.0
    got = np.asarray(coates_correction(np.array([50.0, 25.0, 25.0, 0.0]), n))
    # 50/100 -> -log(0.5); 25/50 -> -log(0.5); 25/25 took every remaining iteration -> inf;
    # no iterations left -> inf
    np.testing.assert_allclose(got[:2], [np.log(2.0), np.log(2.0)], rtol=1e-15)
    assert np.isinf(got[2]) and got[2] > 0
    assert np.isinf(got[3]) and got[3] > 0
    np.testing.assert_array_equal(np.asarray(coates_correction(np.zeros(4), n)), 0.0)


def test_coates_is_identity_to_first_order_at_low_counts():
    c = np.array([1.0, 2.0, 3.0])
    n = 1e9
    np.testing.assert_allclose(np.asarray(coates_correction(c, n)), c / n, rtol=1e-8)
