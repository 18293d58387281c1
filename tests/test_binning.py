"""Exact Gaussian-IRF binning: known values, limits, precision and gradients."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.stats import norm

from nlosplan._jax import jax, jnp
from nlosplan.sensor_models import binning

# jit once per shape: eager dispatch compiles every primitive separately (slow)
bin_impulses = jax.jit(binning.bin_impulses)
bin_boxes = jax.jit(binning.bin_boxes)


def _edges(n_bins, width=100.0, start=0.0, dtype=np.float64):
    return (start + width * np.arange(n_bins + 1)).astype(dtype)


def _ref_impulses(times, weights, edges, sigma):
    """Independent float64 reference from scipy's normal CDF."""
    times = np.asarray(times, np.float64)
    weights = np.asarray(weights, np.float64)
    edges = np.asarray(edges, np.float64)
    if sigma == 0:
        cdf = (edges[None, :] > times[:, None]).astype(float)
    else:
        cdf = norm.cdf((edges[None, :] - times[:, None]) / sigma)
    return (np.diff(cdf, axis=1) * weights[:, None]).sum(axis=0)


# ----------------------------------------------------------------- sigma == 0
def test_docstring_example_exact():
    h = binning.bin_impulses(np.array([150.0]), np.array([2.0]), np.arange(0.0, 500.0, 100.0), 0.0)
    np.testing.assert_array_equal(np.asarray(h), [0.0, 2.0, 0.0, 0.0])


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_impulse_at_bin_centre_sigma0_lands_in_one_bin(dtype):
    edges = _edges(8, dtype=dtype)
    for j in range(8):
        t = np.array([100.0 * j + 50.0], dtype)
        h = np.asarray(bin_impulses(t, np.array([3.5], dtype), edges, 0.0))
        assert h.dtype == dtype
        expected = np.zeros(8)
        expected[j] = 3.5
        np.testing.assert_array_equal(h, expected)


def test_impulse_exactly_on_edge_goes_right():
    edges = _edges(6)
    for j in range(6):  # j == 0 is the window's left edge: stays in bin 0
        h = np.asarray(bin_impulses(np.array([100.0 * j]), np.array([1.0]), edges, 0.0))
        expected = np.zeros(6)
        expected[j] = 1.0
        np.testing.assert_array_equal(h, expected)
    # on the window's right edge: lost (bins are [a, b))
    h = np.asarray(bin_impulses(np.array([600.0]), np.array([1.0]), edges, 0.0))
    np.testing.assert_array_equal(h, np.zeros(6))


def test_impulses_outside_window_are_lost_sigma0():
    edges = _edges(4)
    h = np.asarray(bin_impulses(np.array([-1.0, 400.0, 1e9]), np.array([1.0, 2.0, 3.0]), edges, 0.0))
    np.testing.assert_array_equal(h, np.zeros(4))


def test_batched_leading_axes_are_independent():
    edges = _edges(10)
    rng = np.random.default_rng(0)
    t = rng.uniform(100, 900, size=(2, 3, 5))
    w = rng.uniform(0, 2, size=(2, 3, 5))
    h = np.asarray(bin_impulses(t, w, edges, 37.0))
    assert h.shape == (2, 3, 10)
    for i in range(2):
        for j in range(3):
            np.testing.assert_allclose(h[i, j], _ref_impulses(t[i, j], w[i, j], edges, 37.0), rtol=0, atol=1e-13)


# ------------------------------------------------------------- Gaussian masses
@pytest.mark.parametrize("sigma", [0.3, 12.5, 100.0, 777.0])
def test_gaussian_mass_matches_scipy_cdf_differences(sigma):
    edges = _edges(40, width=50.0, start=-300.0)
    rng = np.random.default_rng(1)
    t = rng.uniform(-400.0, 1900.0, size=9)
    w = rng.uniform(0.1, 5.0, size=9)
    h = np.asarray(bin_impulses(t, w, edges, sigma))
    np.testing.assert_allclose(h, _ref_impulses(t, w, edges, sigma), rtol=0, atol=1e-12)


def test_gaussian_far_tails_are_relatively_accurate():
    """Bins 10-30 sigma away keep full relative precision (no 1 - Phi cancellation)."""
    sigma = 10.0
    edges = _edges(60, width=10.0)
    t = np.array([300.0])
    h = np.asarray(bin_impulses(t, np.array([1.0]), edges, sigma))
    z = (edges - 300.0) / sigma
    # upper tail right of the arrival, lower tail left of it
    right = norm.sf(z[:-1]) - norm.sf(z[1:])
    left = norm.cdf(z[1:]) - norm.cdf(z[:-1])
    ref = np.where(z[:-1] >= 0, right, left)
    far = np.abs(z[:-1] - 0.0) > 10
    assert np.all(h[far] > 0)
    np.testing.assert_allclose(h[far], ref[far], rtol=1e-10)


def test_single_bin():
    edges = np.array([0.0, 100.0])
    h = np.asarray(bin_impulses(np.array([30.0, 100.0, -50.0]), np.array([1.0, 2.0, 4.0]), edges, 40.0))
    assert h.shape == (1,)
    np.testing.assert_allclose(h, _ref_impulses([30.0, 100.0, -50.0], [1.0, 2.0, 4.0], edges, 40.0), atol=1e-14)
    hb = np.asarray(bin_boxes(np.array([20.0]), 50.0, np.array([2.0]), edges, 0.0))
    np.testing.assert_allclose(hb, [2.0], rtol=1e-15)


def test_4096_bins():
    edges = _edges(4096, width=25.0)
    t = np.array([1234.5, 50_000.0, 101_000.0])
    w = np.array([1.0, 2.0, 3.0])
    h = np.asarray(bin_impulses(t, w, edges, 60.0))
    assert h.shape == (4096,)
    np.testing.assert_allclose(h, _ref_impulses(t, w, edges, 60.0), rtol=0, atol=1e-12)
    assert abs(h.sum() - 6.0) < 1e-12
    # sigma 0: each impulse in exactly its bin
    h0 = np.asarray(bin_impulses(t, w, edges, 0.0))
    assert np.count_nonzero(h0) == 3
    np.testing.assert_array_equal(h0[[49, 2000, 4040]], w)


def test_jitter_much_larger_than_window_is_pdf_times_width():
    edges = _edges(10)
    for sigma in (1e6, 1e9):
        h = np.asarray(bin_impulses(np.array([500.0]), np.array([7.0]), edges, sigma))
        assert np.all(np.isfinite(h)) and np.all(h > 0)
        centres = 0.5 * (edges[1:] + edges[:-1])
        ref = 7.0 * norm.pdf(centres, loc=500.0, scale=sigma) * 100.0
        np.testing.assert_allclose(h, ref, rtol=1e-6)
        assert h.sum() < 1e-3 * 7.0


def test_huge_next_to_small_float32_matches_float64():
    """A 1e7 return 6 sigma from a 10-count return: the small one survives in float32."""
    sigma = 50.0
    edges64 = _edges(64, width=50.0)
    t = np.array([1000.0, 1300.0, 2400.0])  # big, small at 6 sigma, small far away
    w = np.array([1e7, 10.0, 10.0])
    h64 = np.asarray(bin_impulses(t, w, edges64, sigma))
    h32 = np.asarray(bin_impulses(t.astype(np.float32), w.astype(np.float32), edges64.astype(np.float32), np.float32(sigma)))
    assert h32.dtype == np.float32
    for centre in (1300.0, 2400.0):
        j = int(centre // 50)
        region = slice(j - 3, j + 3)
        assert np.all(h64[region] > 1e-3)
        np.testing.assert_allclose(h32[region], h64[region], rtol=1e-3)
    # and the far right tail of the big return (relative accuracy, no cancellation)
    np.testing.assert_allclose(h32[25:27], h64[25:27], rtol=1e-3)


# ----------------------------------------------------------------------- boxes
def test_box_sigma0_splits_by_overlap_fraction():
    edges = _edges(5)
    h = np.asarray(bin_boxes(np.array([130.0]), 200.0, np.array([4.0]), edges, 0.0))
    # [130, 330): 70 in bin 1, 100 in bin 2, 30 in bin 3
    np.testing.assert_allclose(h, 4.0 * np.array([0.0, 0.35, 0.5, 0.15, 0.0]), rtol=1e-14, atol=1e-15)
    # a box hanging over the window's edges loses exactly the outside part
    h = np.asarray(bin_boxes(np.array([-50.0, 450.0]), 100.0, np.array([1.0, 1.0]), edges, 0.0))
    np.testing.assert_allclose(h, [0.5, 0.0, 0.0, 0.0, 0.5], atol=1e-15)


def test_box_inside_one_bin_sigma0():
    edges = _edges(3)
    h = np.asarray(bin_boxes(np.array([110.0]), np.array([30.0]), np.array([2.5]), edges, 0.0))
    np.testing.assert_allclose(h, [0.0, 2.5, 0.0], atol=1e-15)


@pytest.mark.parametrize("sigma", [0.0, 5.0, 40.0, 300.0])
def test_box_equals_limit_of_many_impulses(sigma):
    """m midpoint impulses converge to the box (O(1/m^2)); Richardson removes the leading term."""
    edges = _edges(20, width=50.0)
    start, width, mass = 313.0, 170.0, 3.0
    h_box = np.asarray(bin_boxes(np.array([start]), width, np.array([mass]), edges, sigma))

    def impulses(m):
        t = start + width * (np.arange(m) + 0.5) / m
        return np.asarray(bin_impulses(t, np.full(m, mass / m), edges, sigma))

    coarse, fine = impulses(2000), impulses(4000)
    if sigma == 0:  # step response: error at most one sub-impulse per edge
        np.testing.assert_allclose(h_box, fine, rtol=0, atol=2 * mass / 4000)
        return
    err_coarse = np.abs(coarse - h_box).max()
    err_fine = np.abs(fine - h_box).max()
    assert err_fine < 1e-7 and err_fine < 0.3 * err_coarse  # converging, second order
    np.testing.assert_allclose(h_box, (4 * fine - coarse) / 3, rtol=0, atol=1e-11)


@pytest.mark.parametrize("sigma", [3.0, 60.0])
def test_box_matches_analytic_integral(sigma):
    """Box (*) Gaussian mass in [a, b) = (R(b-u) - R(b-u-h) - R(a-u) + R(a-u-h)) / h, R(x) = x Phi + sigma phi."""
    edges = _edges(16, width=40.0)
    u, h, m = 200.0, 90.0, 2.0

    def ramp(x):
        return x * norm.cdf(x / sigma) + sigma * norm.pdf(x / sigma)

    phi_avg = (ramp(edges - u) - ramp(edges - u - h)) / h
    ref = m * np.diff(phi_avg)
    got = np.asarray(bin_boxes(np.array([u]), h, np.array([m]), edges, sigma))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)


def test_narrow_box_matches_impulse():
    edges = _edges(12, width=50.0)
    got = np.asarray(bin_boxes(np.array([300.0]), 1e-3, np.array([1.0]), edges, 80.0))
    ref = np.asarray(bin_impulses(np.array([300.0 + 5e-4]), np.array([1.0]), edges, 80.0))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize(
    "dtype, start, width, sigma, bad_bin",
    [(np.float32, 1000.0, 10.0, 100.0, 23), (np.float64, 24.0, 1.3, 10.0, 4)],
    ids=["float32", "float64"],
)
def test_box_far_tail_is_not_negative(dtype, start, width, sigma, bad_bin):
    """Expected counts are never negative, also 13-40 sigma from a box.

    ``_psi(z) = phi(z) - z * Q(z)`` cancels catastrophically in the far tail;
    differences of window tails then come out slightly negative (about -8e-37
    in float32 in bin 23 here, -3e-307 in float64 in bin 4), which turns
    ``log(expected)`` into NaN downstream.
    """
    edges = (100.0 * np.arange(65)).astype(dtype)
    h = np.asarray(bin_boxes(np.array([start], dtype), dtype(width), np.ones(1, dtype), edges, dtype(sigma)))
    assert h[bad_bin] >= 0.0, h[bad_bin]
    assert np.all(h >= 0.0), (np.flatnonzero(h < 0), h[h < 0])


def test_box_dtype_follows_input():
    edges = _edges(8).astype(np.float32)
    h = bin_boxes(np.array([100.0], np.float32), np.float32(50.0), np.array([1.0], np.float32), edges, np.float32(20.0))
    assert h.dtype == jnp.float32
    np.testing.assert_allclose(np.asarray(h).sum(), 1.0, rtol=1e-6)


# ------------------------------------------------------------------- gradients
def _fd(f, x, eps):
    return (f(x + eps) - f(x - eps)) / (2 * eps)


_EDGES = _edges(24, width=50.0)
_PROBE = np.random.default_rng(7).normal(size=24)
_T = np.array([333.3, 610.0, 777.7])
_W = np.array([1.0, 2.5, 0.7])


def _loss_impulses(t, sigma):
    return jnp.dot(bin_impulses(t, _W, _EDGES, sigma), _PROBE)


def _loss_boxes(t, sigma):
    return jnp.dot(bin_boxes(t, 70.0, _W, _EDGES, sigma), _PROBE)


_GRADS = {f: jax.jit(jax.grad(f, argnums=(0, 1))) for f in (_loss_impulses, _loss_boxes)}
_JITTED = {f: jax.jit(f) for f in (_loss_impulses, _loss_boxes)}


@pytest.mark.parametrize("loss", [_loss_impulses, _loss_boxes], ids=["impulses", "boxes"])
@pytest.mark.parametrize("sigma", [4.0, 35.0, 250.0])
def test_gradients_match_central_differences(loss, sigma):
    g_t, g_s = _GRADS[loss](jnp.asarray(_T), jnp.asarray(sigma))
    loss = _JITTED[loss]
    g_t, g_s = np.asarray(g_t), float(g_s)
    assert np.all(np.isfinite(g_t)) and np.isfinite(g_s)
    eps = 1e-4 * sigma
    fd_s = _fd(lambda s: float(loss(jnp.asarray(_T), s)), sigma, eps)
    np.testing.assert_allclose(g_s, fd_s, rtol=1e-6, atol=1e-10)
    for k in range(_T.size):
        e = np.zeros_like(_T)
        e[k] = 1.0
        fd_t = _fd(lambda a: float(loss(jnp.asarray(_T + a * e), sigma)), 0.0, eps)
        np.testing.assert_allclose(g_t[k], fd_t, rtol=1e-6, atol=1e-10)
    # the gradient is not trivially zero
    assert np.max(np.abs(g_t)) > 1e-6 and abs(g_s) > 1e-8


@pytest.mark.parametrize("loss", [_loss_impulses, _loss_boxes], ids=["impulses", "boxes"])
def test_gradients_finite_at_sigma_zero(loss):
    # includes a time exactly on an edge and one at a bin centre
    t = jnp.asarray([300.0, 625.0, 777.7])
    g_t, g_s = _GRADS[loss](t, jnp.asarray(0.0))
    assert np.all(np.isfinite(np.asarray(g_t)))
    assert np.isfinite(float(g_s))


def test_time_gradient_at_sigma_zero_impulse_is_zero_box_is_overlap_slope():
    t = jnp.asarray([310.0, 625.0, 777.7])  # away from edges (and box ends away from edges)
    g_imp, _ = _GRADS[_loss_impulses](t, jnp.asarray(0.0))
    np.testing.assert_array_equal(np.asarray(g_imp), 0.0)  # piecewise constant in t
    g_box, _ = _GRADS[_loss_boxes](t, jnp.asarray(0.0))
    # piecewise linear in t: derivative = w * (probe[bin of end] - probe[bin of start]) / width
    j0 = (np.asarray(t) // 50).astype(int)
    j1 = ((np.asarray(t) + 70.0) // 50).astype(int)
    np.testing.assert_allclose(np.asarray(g_box), _W * (_PROBE[j1] - _PROBE[j0]) / 70.0, rtol=1e-12)


def test_gradient_wrt_weights_is_the_binning_matrix():
    g = jax.grad(lambda w: jnp.dot(bin_impulses(_T, w, _EDGES, 20.0), _PROBE))(jnp.asarray(_W))
    ref = np.array([_ref_impulses([t], [1.0], _EDGES, 20.0) @ _PROBE for t in _T])
    np.testing.assert_allclose(np.asarray(g), ref, rtol=1e-10, atol=1e-13)


def test_jit_and_vmap_agree_with_eager():
    t = jnp.asarray(np.random.default_rng(3).uniform(100, 1100, size=(4, 3)))
    w = jnp.ones((4, 3))
    eager = binning.bin_impulses(t, w, _EDGES, 30.0)
    jitted = bin_impulses(t, w, _EDGES, 30.0)
    vm = jax.jit(jax.vmap(lambda a, b: binning.bin_impulses(a, b, _EDGES, 30.0)))(t, w)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(eager), rtol=1e-13, atol=1e-15)
    np.testing.assert_allclose(np.asarray(vm), np.asarray(eager), rtol=1e-13, atol=1e-15)
