"""Exact binning of arrival times through a Gaussian impulse response.

Pure JAX functions; they follow the dtype of their inputs (float32 stays
float32) and are differentiable in times, weights, edges and ``sigma``.

Notes
-----
An impulse of weight ``w`` at time ``t`` seen through a Gaussian of standard
deviation ``sigma`` puts

    w * [Phi((b - t) / sigma) - Phi((a - t) / sigma)]

into the bin ``[a, b)``. Differences of ``Phi`` near 1 cancel badly, so each
edge keeps both tails, ``L = Phi(z)`` and ``U = 1 - Phi(z)``, each from
``erfc`` in the regime where it is accurate, and a bin is

    U(a) - U(b)            if a >= t (bin right of the arrival)
    L(b) - L(a)            if b <= t (bin left of the arrival)
    1 - U(b) - L(a)        otherwise.

At ``sigma == 0`` the Gaussian becomes a step (exact, no division by zero).

A box (uniform density of mass ``m`` on ``[u, u + h]``) uses the same scheme
with ``Phi`` replaced by its average over a window of width ``h``; with the
ramp antiderivative ``R(x) = max(x, 0) + sigma * psi(|x| / sigma)``,
``psi(z) = phi(z) - z * Q(z)`` (``Q`` the upper tail), the window averages
have closed forms, again evaluated tail-first.
"""

from __future__ import annotations

from nlosplan._jax import jax, jnp

_SQRT2 = 1.4142135623730951
_INV_SQRT_2PI = 0.3989422804014327


def _tails(z):
    """Gaussian tails ``(Phi(z), 1 - Phi(z))`` from one ``erfc``.

    The smaller tail is computed directly (accurate to full relative
    precision); the larger is its complement. :func:`_combine` only ever uses
    the small tail where it matters, so one ``erfc`` per edge suffices.
    """
    negative = z < 0
    small = 0.5 * jax.scipy.special.erfc(jnp.where(negative, -z, z) / _SQRT2)
    big = 1.0 - small
    return jnp.where(negative, small, big), jnp.where(negative, big, small)


def _combine(lower_a, upper_a, lower_b, upper_b, right_of, left_of):
    """Mass in ``[a, b)`` from per-edge tails, choosing the cancellation-free form."""
    middle = 1.0 - upper_b - lower_a
    return jnp.where(right_of, upper_a - upper_b, jnp.where(left_of, lower_b - lower_a, middle))


def bin_impulses(times_ps, weights, edges_ps, sigma_ps):
    """Integrate Gaussian-blurred impulses over bins, exactly.

    Parameters
    ----------
    times_ps : array, shape (..., K)
        Arrival times, picoseconds.
    weights : array, shape (..., K)
        Weight (expected photons) of each arrival.
    edges_ps : array, shape (B + 1,)
        Increasing bin edges, picoseconds.
    sigma_ps : float or scalar array
        Standard deviation of the Gaussian impulse response, ps (>= 0).

    Returns
    -------
    array, shape (..., B)
        Expected counts per bin. Mass outside ``[edges[0], edges[-1])`` is lost.

    Examples
    --------
    >>> import numpy as np
    >>> h = bin_impulses(np.array([150.0]), np.array([2.0]), np.arange(0.0, 500.0, 100.0), 0.0)
    >>> np.asarray(h).tolist()
    [0.0, 2.0, 0.0, 0.0]
    """
    times_ps = jnp.asarray(times_ps)
    dtype = jnp.result_type(times_ps, jnp.asarray(weights), float)
    times = times_ps.astype(dtype)[..., :, None]  # (..., K, 1)
    w = jnp.asarray(weights, dtype)
    edges = jnp.asarray(edges_ps, dtype)
    sigma = jnp.asarray(sigma_ps, dtype)
    positive = sigma > 0
    safe_sigma = jnp.where(positive, sigma, 1.0)

    d = edges - times  # (..., K, B+1): edge minus arrival
    lower, upper = _tails(d / safe_sigma)
    step_lower = (d > 0).astype(dtype)  # Phi at sigma -> 0 (arrival on an edge goes right)
    lower = jnp.where(positive, lower, step_lower)
    upper = jnp.where(positive, upper, 1.0 - step_lower)
    da, db = d[..., :-1], d[..., 1:]
    mass = _combine(lower[..., :-1], upper[..., :-1], lower[..., 1:], upper[..., 1:], da >= 0, db <= 0)
    mass = jnp.maximum(mass, 0.0)
    return jnp.einsum("...kb,...k->...b", mass, w)


def _psi(z):
    """``phi(z) - z * Q(z)`` for ``z >= 0`` (decays like ``phi(z) / z**2``)."""
    upper = 0.5 * jax.scipy.special.erfc(z / _SQRT2)
    return _INV_SQRT_2PI * jnp.exp(-0.5 * z * z) - z * upper


def _window_tails(x, h, sigma, positive):
    """Average of ``Phi(s / sigma)`` and of ``Q(s / sigma)`` over ``s in [x - h, x]``.

    ``x`` is edge minus box start. Each average is computed in its accurate
    regime: ``Q``-average when the window lies right of 0, ``Phi``-average when
    left of 0, either one inside.
    """
    safe_sigma = jnp.where(positive, sigma, 1.0)
    lo = x - h
    # Phi-average for windows left of 0: (R(x) - R(x-h)) / h with R(x<=0) = sigma*psi(-x/sigma)
    ax = jnp.abs(x) / safe_sigma
    alo = jnp.abs(lo) / safe_sigma
    tail_x = safe_sigma * _psi(ax)
    tail_lo = safe_sigma * _psi(alo)
    # general R(x) = max(x,0) + sigma*psi(|x|/sigma); S(x) = R(-x) = max(-x,0) + sigma*psi(|x|/sigma)
    ramp_diff = jnp.clip(x, 0.0, None) - jnp.clip(lo, 0.0, None)  # overlap of window with s > 0
    phi_avg = (ramp_diff + tail_x - tail_lo) / h
    q_avg = 1.0 - phi_avg
    # accurate forms in the tails
    phi_left = (tail_x - tail_lo) / h  # x <= 0: both ramps are zero
    q_right = (tail_lo - tail_x) / h  # lo >= 0: S ramps are zero
    phi_avg = jnp.where(x <= 0, phi_left, jnp.where(lo >= 0, 1.0 - q_right, phi_avg))
    q_avg = jnp.where(lo >= 0, q_right, jnp.where(x <= 0, 1.0 - phi_left, q_avg))
    # narrow boxes (h << sigma): the window average is Phi at the midpoint
    mid_lower, mid_upper = _tails((x - 0.5 * h) / safe_sigma)
    narrow = h < 1e-3 * safe_sigma
    phi_avg = jnp.where(narrow, mid_lower, phi_avg)
    q_avg = jnp.where(narrow, mid_upper, q_avg)
    # sigma == 0: fraction of the box left of the edge
    frac = jnp.clip(x / h, 0.0, 1.0)
    phi_avg = jnp.where(positive, phi_avg, frac)
    q_avg = jnp.where(positive, q_avg, 1.0 - frac)
    return phi_avg, q_avg


def bin_boxes(starts_ps, widths_ps, masses, edges_ps, sigma_ps):
    """Integrate Gaussian-blurred uniform boxes over bins, exactly.

    Parameters
    ----------
    starts_ps : array, shape (..., K)
        Left end of each box, picoseconds.
    widths_ps : array, shape (..., K) or scalar
        Box widths, picoseconds (> 0).
    masses : array, shape (..., K)
        Total mass (expected photons) in each box, spread uniformly.
    edges_ps : array, shape (B + 1,)
        Increasing bin edges, picoseconds.
    sigma_ps : float or scalar array
        Standard deviation of the Gaussian impulse response, ps (>= 0).

    Returns
    -------
    array, shape (..., B)
        Expected counts per bin.

    Notes
    -----
    Piecewise-constant arrival densities and measured (sampled) pulse shapes
    are sums of boxes, so both are binned without any sampling error.
    """
    starts = jnp.asarray(starts_ps)
    dtype = jnp.result_type(starts, jnp.asarray(masses), float)
    starts = starts.astype(dtype)
    widths = jnp.broadcast_to(jnp.asarray(widths_ps, dtype), starts.shape)
    m = jnp.asarray(masses, dtype)
    edges = jnp.asarray(edges_ps, dtype)
    sigma = jnp.asarray(sigma_ps, dtype)
    positive = sigma > 0

    x = edges - starts[..., :, None]  # (..., K, B+1)
    h = widths[..., :, None]
    lower, upper = _window_tails(x, h, sigma, positive)
    xa, xb = x[..., :-1], x[..., 1:]
    hh = h
    right_of = (xa - hh) >= 0  # whole box left of the bin's left edge
    left_of = xb <= 0  # whole box right of the bin's right edge
    mass = _combine(lower[..., :-1], upper[..., :-1], lower[..., 1:], upper[..., 1:], right_of, left_of)
    # far tails (> ~13 sigma) of psi differences can round to -1e-37; mass is never negative
    mass = jnp.maximum(mass, 0.0)
    return jnp.einsum("...kb,...k->...b", mass, m)
