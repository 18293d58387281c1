"""Histogram formation: arrivals per zone -> expected counts -> sampled counts.

The numerical core, :func:`expected_counts`, takes every sensor quantity as
an explicit (traceable) argument so it can be ``jit``-ed, ``vmap``-ed over
batches and differentiated with respect to jitter, pulse width, bin width,
photon scale and arrival times. :func:`expected_histogram` and
:func:`sample_histogram` are the convenient front ends from a
:class:`~nlosplan.sensor_models.config.SensorConfig`.

Notes
-----
Forward model per zone and bin ``j`` (per laser iteration):

    lam_j = s * sum_k w_k * IRF_j(t_k) + x * IRF_j(0) + (a * L + d) * dt

with ``s`` the photon scale, ``IRF_j(t)`` the mass that an arrival at ``t``
puts into bin ``j`` through the impulse response (measured pulse, if any,
convolved with a Gaussian of ``sigma^2 = sigma_pulse^2 + sigma_jitter^2``),
``x`` the crosstalk at zero optical path, ``a`` the ambient rate (``L`` = 1
with lights on, 0 off), ``d`` the dark rate and ``dt`` the bin width in
seconds. Expected counts are ``N * lam_j`` without pile-up or Coates'
``N * (1 - e^{-lam_j}) e^{-sum_{i<j} lam_i}`` with it, then Poisson noise and
the 24-bit clip.
"""

from __future__ import annotations

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.sensor_models.binning import bin_boxes, bin_impulses
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.counts import pileup_expected, sample_poisson, saturate


def pulse_boxes(sensor: SensorConfig) -> tuple[np.ndarray, float, np.ndarray] | None:
    """The measured pulse as boxes: ``(offsets_ps (P,), width_ps, masses (P,))``.

    ``None`` when the sensor has no measured pulse (Gaussian only).
    """
    if sensor.pulse_shape is None:
        return None
    p = np.asarray(sensor.pulse_shape, dtype=np.float64)
    offsets = sensor.pulse_shape_t0_ps + sensor.pulse_shape_step_ps * np.arange(p.size)
    return offsets, float(sensor.pulse_shape_step_ps), p


def bin_arrivals(times_ps, weights, edges_ps, sigma_ps, pulse=None):
    """Bin arrivals through the full impulse response.

    Parameters
    ----------
    times_ps, weights : array, shape (..., K)
        Arrival times (ps) and weights.
    edges_ps : array, shape (B + 1,)
    sigma_ps : scalar
        Gaussian standard deviation, ps.
    pulse : tuple or None
        ``(offsets (P,), width, masses (P,))`` from :func:`pulse_boxes`.

    Returns
    -------
    array, shape (..., B)
    """
    if pulse is None:
        return bin_impulses(times_ps, weights, edges_ps, sigma_ps)
    offsets, width, masses = pulse
    t = jnp.asarray(times_ps)
    w = jnp.asarray(weights)
    dtype = jnp.result_type(t, w, float)
    starts = t[..., :, None] + jnp.asarray(offsets, dtype)
    m = w[..., :, None] * jnp.asarray(masses, dtype)
    flat = starts.shape[:-2] + (starts.shape[-2] * starts.shape[-1],)
    return bin_boxes(starts.reshape(flat), width, m.reshape(flat), edges_ps, sigma_ps)


def expected_counts(
    times_ps,
    weights,
    *,
    edges_ps,
    sigma_ps,
    photon_scale,
    iterations,
    background_per_bin=0.0,
    crosstalk=0.0,
    pulse=None,
    pileup: bool = False,
    max_count=None,
):
    """Expected recorded counts per bin (pure, traceable core).

    Parameters
    ----------
    times_ps, weights : array, shape (..., K)
        Arrival times (ps) and transport weights per zone.
    edges_ps : array, shape (B + 1,)
        Bin edges, ps.
    sigma_ps : scalar
        Gaussian impulse-response standard deviation, ps.
    photon_scale : scalar
        Detected photons per iteration per unit weight.
    iterations : scalar
        Laser iterations per histogram.
    background_per_bin : scalar or array broadcastable to (..., B)
        Ambient + dark photons per iteration per bin.
    crosstalk : scalar
        Crosstalk photons per iteration at zero optical path.
    pulse : tuple or None
        Measured pulse boxes (static).
    pileup : bool
        Apply Coates pile-up (static).
    max_count : int or None
        Clip expected counts here (24-bit saturation); None to skip.

    Returns
    -------
    array, shape (..., B)
        Expected counts, same float dtype as the inputs.
    """
    w = jnp.asarray(weights)
    lam = bin_arrivals(times_ps, photon_scale * w, edges_ps, sigma_ps, pulse)
    dtype = lam.dtype
    if not (isinstance(crosstalk, (int, float)) and crosstalk == 0):
        zero = jnp.zeros(lam.shape[:-1] + (1,), dtype)
        xt = jnp.full(lam.shape[:-1] + (1,), crosstalk, dtype)
        lam = lam + bin_arrivals(zero, xt, edges_ps, sigma_ps, pulse)
    return counts_from_rates(lam, iterations=iterations, background_per_bin=background_per_bin,
                             pileup=pileup, max_count=max_count)


def counts_from_rates(lam, *, iterations, background_per_bin=0.0, pileup: bool = False, max_count=None):
    """Expected recorded counts from binned photons per iteration.

    Parameters
    ----------
    lam : array, shape (..., B)
        Signal photons per iteration per bin (already through the impulse response).
    iterations : scalar
        Laser iterations per histogram.
    background_per_bin : scalar or array broadcastable to (..., B)
        Ambient + dark photons per iteration per bin.
    pileup : bool
        Apply Coates pile-up (static).
    max_count : int or None
        Clip expected counts here (24-bit saturation); None to skip.

    Returns
    -------
    array, shape (..., B)
    """
    dtype = lam.dtype
    if not (isinstance(background_per_bin, (int, float)) and background_per_bin == 0):
        lam = lam + jnp.asarray(background_per_bin, dtype)
    counts = pileup_expected(lam, iterations) if pileup else iterations * lam
    if max_count is not None:
        counts = jnp.minimum(counts, jnp.asarray(max_count, dtype))
    return counts


def background_per_bin(sensor: SensorConfig, lights_on: bool) -> float:
    """Ambient (if lights on) plus dark photons per iteration per bin."""
    rate = sensor.dark_rate_hz + (sensor.ambient_rate_hz if lights_on else 0.0)
    return rate * sensor.bin_width_ps * 1e-12


def expected_histogram(sensor: SensorConfig, times_ps, weights, *, lights_on: bool = True, dtype=None):
    """Expected counts of ``sensor`` for arrivals per zone.

    Parameters
    ----------
    sensor : SensorConfig
    times_ps, weights : array, shape (..., K)
        Arrival times (ps) and transport weights; leading axes are usually
        ``(rows, cols)`` or a batch.
    lights_on : bool
        Include ambient light.
    dtype : numpy dtype, optional
        Compute in this float dtype (default: that of the inputs).

    Returns
    -------
    jax array, shape (..., n_bins)
        Expected counts (after pile-up and the 24-bit clip, when enabled).
    """
    t = jnp.asarray(times_ps, dtype)
    w = jnp.asarray(weights, dtype)
    dt = jnp.result_type(t, w, float)
    return expected_counts(
        t.astype(dt),
        w.astype(dt),
        edges_ps=jnp.asarray(sensor.bin_edges_ps(), dt),
        sigma_ps=sensor.sigma_ps,
        photon_scale=sensor.photon_scale,
        iterations=float(sensor.iterations),
        background_per_bin=background_per_bin(sensor, lights_on),
        crosstalk=sensor.crosstalk,
        pulse=pulse_boxes(sensor),
        pileup=sensor.pileup,
        max_count=sensor.max_count if sensor.saturation else None,
    )


def sample_counts(key, mean, *, saturation: bool = True, max_count: int | None = None):
    """Poisson-sample expected counts and apply the register clip.

    Parameters
    ----------
    key : jax.random key
    mean : array, shape (...)
        Expected counts.
    saturation : bool
        Clip at ``max_count`` (24-bit by default).

    Returns
    -------
    array of int64, shape (...)
    """
    counts = sample_poisson(key, mean)
    if saturation:
        counts = saturate(counts) if max_count is None else saturate(counts, max_count)
    return counts


def sample_histogram(key, sensor: SensorConfig, times_ps, weights, *, lights_on: bool = True, repeats: int = 1):
    """Noisy histograms: expected counts, Poisson noise, saturation.

    Parameters
    ----------
    key : jax.random key or int
        Explicit randomness (an int is turned into a key).
    sensor : SensorConfig
    times_ps, weights : array, shape (..., K)
    lights_on : bool
    repeats : int
        Independent captures.

    Returns
    -------
    array of int64, shape (repeats, ..., n_bins)
    """
    if isinstance(key, (int, np.integer)):
        key = jax.random.key(int(key))
    mean = expected_histogram(sensor, times_ps, weights, lights_on=lights_on)
    mean = jnp.broadcast_to(mean, (repeats,) + mean.shape)
    return sample_counts(key, mean, saturation=sensor.saturation, max_count=sensor.max_count)


def apply_jitter(histogram, fwhm_ps, bin_width_ps):
    """Blur existing histograms with Gaussian timing jitter (DENALI's jitter study).

    Each bin is treated as a uniform box of its width and re-binned through a
    Gaussian of the given FWHM, exactly; mass blurred past either end of the
    window is lost, as it would be on the sensor.

    Parameters
    ----------
    histogram : array, shape (..., B)
        Counts or expected counts.
    fwhm_ps : float
        Jitter FWHM, ps (0 returns the input unchanged).
    bin_width_ps : float
        Bin width, ps.

    Returns
    -------
    array, shape (..., B), float
    """
    h = jnp.asarray(histogram)
    dtype = jnp.result_type(h, float)
    h = h.astype(dtype)
    n = h.shape[-1]
    edges = jnp.arange(n + 1, dtype=dtype) * bin_width_ps
    sigma = jnp.asarray(fwhm_ps, dtype) / 2.3548200450309493
    return bin_boxes(edges[:-1], bin_width_ps, h, edges, sigma)
