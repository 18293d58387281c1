"""The noise model (sensor_models/noise.py): rates to counts per bin, captures drawn from expectations."""

from __future__ import annotations

import numpy as np
import pytest

from nlosplan._jax import jax, jnp
from nlosplan.constants import MAX_COUNT_24BIT
from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.sensor_models import noise as N
from nlosplan.sensor_models.noise import CaptureNoise

sample_poisson = jax.jit(N.sample_poisson)

# ------------------------------------------------------------------ rates -> counts per bin


def test_per_bin_and_rate_hz_are_inverse_and_match_the_hand_formula():
    assert N.per_bin(2.0e6, 250.0) == 2.0e6 * 250.0 * 1e-12
    assert N.rate_hz(N.per_bin(3.0e5, 91.0) * 40_000, 40_000, 91.0) == pytest.approx(3.0e5, rel=1e-15)
    got = np.asarray(jax.jit(N.per_bin)(jnp.asarray([1e6, 2e6]), jnp.asarray(100.0)))
    np.testing.assert_allclose(got, [1e-4, 2e-4], rtol=1e-15)


def test_floor_is_dark_plus_ambient_only_with_the_lights_on():
    s = preset("tmf8828-3x3-short").replace(dark_rate_hz=1.0e5, ambient_rate_hz=4.0e6)
    on, off = N.floor_per_bin(s, True), N.floor_per_bin(s, False)
    assert off == 1.0e5 * s.bin_width_ps * 1e-12
    assert on == (1.0e5 + 4.0e6) * s.bin_width_ps * 1e-12
    assert N.floor_counts(s, True) == on * s.iterations
    assert N.floor_rate_hz(1.0e5, 4.0e6, 0.0) == 1.0e5


# ------------------------------------------------------------------ sampling with a JAX key
_N_SAMPLES = 100_000


@pytest.mark.parametrize("mean", [3.0, 1e3, 1e9, 1e12])
def test_sample_poisson_mean_and_variance(mean):
    x = sample_poisson(jax.random.key(11), jnp.full((_N_SAMPLES,), mean))
    assert x.dtype == jnp.int64
    x = np.asarray(x)
    assert np.all(x >= 0)
    if mean > N.EXACT_POISSON_MAX_MEAN:
        # normal path: no overflow, values near the mean
        assert np.all(np.abs(x - mean) < 10 * np.sqrt(mean))
    m = x.astype(np.float64).mean()
    v = x.astype(np.float64).var(ddof=1)
    se_mean = np.sqrt(mean / _N_SAMPLES)
    se_var = np.sqrt((2 * mean**2 + mean) / _N_SAMPLES)
    assert abs(m - mean) < 5 * se_mean, (m, mean)
    assert abs(v - mean) < 5 * se_var, (v, mean)


def test_sample_poisson_small_mean_distribution():
    """Exact path: empirical pmf at mean 3 matches the Poisson pmf."""
    from scipy.stats import poisson

    x = np.asarray(sample_poisson(jax.random.key(3), jnp.full((_N_SAMPLES,), 3.0)))
    freq = np.bincount(x, minlength=12)[:12] / _N_SAMPLES
    pmf = poisson.pmf(np.arange(12), 3.0)
    assert np.all(np.abs(freq - pmf) < 5 * np.sqrt(pmf * (1 - pmf) / _N_SAMPLES) + 1e-4)


def test_sample_poisson_zero_mean_is_zero_and_mixed_means():
    means = jnp.asarray([0.0, 0.0, 5.0, 1e12, 0.0, 4e18])
    x = np.asarray(N.sample_poisson(jax.random.key(0), means))
    assert x.dtype == np.int64
    assert x[0] == 0 and x[1] == 0 and x[4] == 0
    assert 0 <= x[2] < 100
    assert abs(x[3] - 1e12) < 1e8
    assert 3.9e18 < x[5] <= 9e18  # no int64 overflow
    np.testing.assert_array_equal(np.asarray(N.sample_poisson(jax.random.key(9), jnp.zeros((3, 4)))), 0)


def test_sample_poisson_float32_means_and_determinism():
    means = jnp.asarray([2.0, 1e9], jnp.float32)
    a = np.asarray(N.sample_poisson(jax.random.key(1), means))
    b = np.asarray(N.sample_poisson(jax.random.key(1), means))
    assert a.dtype == np.int64
    np.testing.assert_array_equal(a, b)
    assert abs(a[1] - 1e9) < 10 * np.sqrt(1e9)


# ------------------------------------------------------------------ CaptureNoise
def test_capture_noise_of_a_sensor_clips_at_24_bits_only_with_saturation():
    s = preset("tmf8828-3x3-short")
    assert CaptureNoise.of(s).max_count == MAX_COUNT_24BIT == 2**24 - 1
    assert CaptureNoise.of(s.replace(saturation=False)).max_count is None


def test_draw_with_a_key_clips_and_equals_the_unclipped_draw_below_the_clip():
    mean = jnp.asarray([0.0, 10.0, 1e9, 1e12])
    sat = np.asarray(CaptureNoise(MAX_COUNT_24BIT).draw(jax.random.key(4), mean))
    raw = np.asarray(CaptureNoise().draw(jax.random.key(4), mean))
    assert sat.dtype == raw.dtype == np.int64
    assert sat[0] == 0
    np.testing.assert_array_equal(sat[2:], MAX_COUNT_24BIT)
    assert raw[3] > MAX_COUNT_24BIT
    np.testing.assert_array_equal(sat, np.minimum(raw, MAX_COUNT_24BIT))
    np.testing.assert_array_equal(sat, np.minimum(np.asarray(N.sample_poisson(jax.random.key(4), mean)), MAX_COUNT_24BIT))


def test_draw_is_traceable_with_the_noise_as_a_static_argument():
    noise = CaptureNoise(100)
    f = jax.jit(lambda k, m, nz: nz.draw(k, m), static_argnums=2)
    out = np.asarray(jax.vmap(lambda k: f(k, jnp.full((50,), 150.0), noise))(jax.random.split(jax.random.key(0), 3)))
    assert out.shape == (3, 50) and out.max() == 100 and out.min() >= 0


def test_draw_with_a_generator_is_numpys_poisson_clipped():
    mean = np.array([[0.0, 2.5, -1e-9], [3e7, 17.0, 1e3]])
    got = CaptureNoise(MAX_COUNT_24BIT).draw(np.random.default_rng(5), mean)
    want = np.minimum(np.random.default_rng(5).poisson(np.maximum(mean, 0.0)), MAX_COUNT_24BIT)
    np.testing.assert_array_equal(got, want)
    assert got[1, 0] == MAX_COUNT_24BIT and got[0, 2] == 0


def test_draw_refuses_other_randomness_in_one_line():
    with pytest.raises(UserError, match="numpy Generator or a JAX random key, not int"):
        CaptureNoise().draw(3, np.ones(2))


def test_mean_of_repeats_has_the_mean_and_variance_of_repeated_captures():
    lam = np.full(200_000, 7.5)
    got = CaptureNoise(MAX_COUNT_24BIT).mean_of_repeats(np.random.default_rng(0), lam, 4)
    assert got.dtype == np.float64
    assert abs(got.mean() - 7.5) < 5 * np.sqrt(7.5 / 4 / lam.size)
    assert abs(got.var() - 7.5 / 4) < 0.03 * 7.5 / 4
    np.testing.assert_allclose(got * 4, np.round(got * 4))  # sums of whole counts


def test_mean_of_repeats_clips_each_capture_not_the_sum():
    """A mean just under the clip: each capture is clipped at max_count, so the mean never exceeds it."""
    top = 1000
    lam = np.full(20_000, 990.0)
    got = CaptureNoise(top).mean_of_repeats(np.random.default_rng(1), lam, 3)
    assert got.max() <= top
    # the clip bites in ~37 % of captures: the mean is E[min(X, top)], below the unclipped 990
    x = np.minimum(np.random.default_rng(2).poisson(990.0, (200_000,)), top).mean()
    assert abs(got.mean() - x) < 0.2
    unclipped = CaptureNoise().mean_of_repeats(np.random.default_rng(1), lam, 3)
    assert unclipped.max() > top and abs(unclipped.mean() - 990.0) < 0.5


def test_mean_of_one_repeat_is_one_draw_of_the_same_generator():
    lam = np.array([1.0, 50.0, 3e7])
    one = CaptureNoise(MAX_COUNT_24BIT).mean_of_repeats(np.random.default_rng(8), lam, 1)
    np.testing.assert_array_equal(one, CaptureNoise(MAX_COUNT_24BIT).draw(np.random.default_rng(8), lam))


def test_mean_of_repeats_checks_its_inputs():
    with pytest.raises(UserError, match="repeats=0 must be >= 1"):
        CaptureNoise().mean_of_repeats(np.random.default_rng(0), np.ones(2), 0)
    with pytest.raises(UserError, match="numpy Generator"):
        CaptureNoise().mean_of_repeats(jax.random.key(0), np.ones(2), 2)
