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
with its exponential tail, convolved with a Gaussian of
``sigma^2 = sigma_pulse^2 + sigma_jitter^2``), ``x`` the crosstalk at zero
optical path, ``a`` the ambient rate (``L`` = 1 with lights on, 0 off), ``d``
the dark rate and ``dt`` the bin width in seconds. The per-zone gain, time
offset and near-field overlap (:mod:`~nlosplan.sensor_models.zone_terms`)
act on each zone's arrivals ``(t_k, w_k)`` first. Expected counts are
``N * lam_j`` without pile-up; with it, each of the zone's ``M`` detectors
records at most one photon per dead time (:func:`~nlosplan.sensor_models.
counts.deadtime_expected`; Coates' ``N (1 - e^{-lam_j}) e^{-sum_{i<j} lam_i}``
for ``M = 1`` and a dead time outlasting the window), then Poisson noise and
the 24-bit clip.
"""

from __future__ import annotations

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.errors import UserError
from nlosplan.sensor_models.binning import bin_boxes, bin_impulses
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.counts import deadtime_expected
from nlosplan.sensor_models.impulse import sigma_of_fwhm
from nlosplan.sensor_models.noise import CaptureNoise, floor_per_bin
from nlosplan.sensor_models.zone_terms import apply_zone_terms_arrivals, walk_shift_ps, zone_values

#: The exponential pulse tail is carried this many windows past the pulse (further light cannot land in the window).
TAIL_WINDOWS = 1.0


def tail_masses(n: int, step_ps: float, decay_ps: float) -> np.ndarray:
    """Masses of ``n`` boxes of width ``step_ps`` under ``exp(-t / decay_ps)``, summing to 1, shape (n,)."""
    edges = np.arange(n + 1, dtype=np.float64) * step_ps
    m = -np.diff(np.exp(-edges / decay_ps))
    return m / m.sum()


def pulse_boxes(sensor: SensorConfig) -> tuple[np.ndarray, float, np.ndarray] | None:
    """The measured pulse as boxes: ``(offsets_ps (P,), width_ps, masses (P,))``.

    ``None`` when the sensor has no measured pulse (Gaussian only). With
    ``pulse_tail_fraction = a > 0`` the samples carry ``1 - a`` of the mass
    and boxes of the same width continue after the last sample with masses
    ``a * (exp(-t_i / tau) - exp(-t_{i+1} / tau))`` (renormalized), out to one
    window past the pulse.
    """
    if sensor.pulse_shape is None:
        return None
    p = np.asarray(sensor.pulse_shape, dtype=np.float64)
    step = float(sensor.pulse_shape_step_ps)
    offsets = sensor.pulse_shape_t0_ps + step * np.arange(p.size)
    a = float(sensor.pulse_tail_fraction)
    if a > 0:
        n = int(np.ceil(TAIL_WINDOWS * sensor.window_ps / step))
        offsets = np.concatenate([offsets, offsets[-1] + step * np.arange(1, n + 1)])
        p = np.concatenate([(1.0 - a) * p, a * tail_masses(n, step, float(sensor.pulse_tail_decay_ps))])
    return offsets, step, p


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
    floor_per_bin=0.0,
    crosstalk=0.0,
    crosstalk_times_ps=0.0,
    pulse=None,
    pileup: bool = False,
    max_count=None,
    spads=1,
    dead_bins=None,
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
    floor_per_bin : scalar or array broadcastable to (..., B)
        The floor (dark + ambient) in photons per iteration per bin (:func:`~nlosplan.sensor_models.noise.floor_per_bin`).
    crosstalk : scalar or array broadcastable to (..., 1)
        Crosstalk photons per iteration at zero optical path (per zone: after its gain).
    crosstalk_times_ps : scalar or array broadcastable to (..., 1)
        When crosstalk arrives, ps (0, or the zone's time offset).
    pulse : tuple or None
        Measured pulse boxes (static).
    pileup : bool
        Apply flux-dependent detection (static).
    max_count : int or None
        Clip expected counts here (24-bit saturation); None to skip.
    spads, dead_bins
        Detectors per zone and their dead time in bins (None: rest of the
        iteration), see :func:`~nlosplan.sensor_models.counts.deadtime_expected`.

    Returns
    -------
    array, shape (..., B)
        Expected counts, same float dtype as the inputs.
    """
    w = jnp.asarray(weights)
    lam = bin_arrivals(times_ps, photon_scale * w, edges_ps, sigma_ps, pulse)
    dtype = lam.dtype
    if not (isinstance(crosstalk, (int, float)) and crosstalk == 0):
        when = jnp.broadcast_to(jnp.asarray(crosstalk_times_ps, dtype), lam.shape[:-1] + (1,))
        xt = jnp.broadcast_to(jnp.asarray(crosstalk, dtype), lam.shape[:-1] + (1,))
        lam = lam + bin_arrivals(when, xt, edges_ps, sigma_ps, pulse)
    return counts_from_rates(lam, iterations=iterations, floor_per_bin=floor_per_bin,
                             pileup=pileup, max_count=max_count, spads=spads, dead_bins=dead_bins)


def counts_from_rates(lam, *, iterations, floor_per_bin=0.0, pileup: bool = False, max_count=None, spads=1,
                      dead_bins=None):
    """Expected recorded counts from binned photons per iteration.

    Parameters
    ----------
    lam : array, shape (..., B)
        Signal photons per iteration per bin (already through the impulse response).
    iterations : scalar
        Laser iterations per histogram.
    floor_per_bin : scalar or array broadcastable to (..., B)
        The floor (dark + ambient) in photons per iteration per bin (:func:`~nlosplan.sensor_models.noise.floor_per_bin`).
    pileup : bool
        Apply flux-dependent detection (static); the floor's photons count toward it.
    max_count : int or None
        Clip expected counts here (24-bit saturation); None to skip.
    spads, dead_bins
        As :func:`~nlosplan.sensor_models.counts.deadtime_expected`.

    Returns
    -------
    array, shape (..., B)
    """
    dtype = lam.dtype
    if not (isinstance(floor_per_bin, (int, float)) and floor_per_bin == 0):
        lam = lam + jnp.asarray(floor_per_bin, dtype)
    counts = deadtime_expected(lam, iterations, spads, dead_bins) if pileup else iterations * lam
    if max_count is not None:
        counts = jnp.minimum(counts, jnp.asarray(max_count, dtype))
    return counts


def dead_bins(sensor: SensorConfig):
    """The sensor's dead time in bins, or None (blind for the rest of the iteration)."""
    return None if sensor.dead_time_ps is None else sensor.dead_time_ps / sensor.bin_width_ps


def expected_histogram(sensor: SensorConfig, times_ps, weights, *, lights_on: bool = True, dtype=None):
    """Expected counts of ``sensor`` for arrivals per zone.

    Parameters
    ----------
    sensor : SensorConfig
    times_ps, weights : array, shape (..., K)
        Arrival times (ps) and transport weights; leading axes are usually
        ``(rows, cols)`` or a batch. A sensor with per-zone terms needs the
        zones as the last leading axes: ``(..., rows, cols, K)`` or ``(..., Z, K)``.
    lights_on : bool
        Include ambient light.
    dtype : numpy dtype, optional
        Compute in this float dtype (default: that of the inputs).

    Returns
    -------
    jax array, shape (..., n_bins)
        Expected counts (after pile-up and the 24-bit clip, when enabled).

    Raises
    ------
    UserError
        Per-zone terms with arrivals that are not laid out per zone.
    """
    t = jnp.asarray(times_ps, dtype)
    w = jnp.asarray(weights, dtype)
    dt = jnp.result_type(t, w, float)
    t, w = t.astype(dt), w.astype(dt)
    zv = zone_values(sensor)
    xt, xt_t = sensor.crosstalk, 0.0
    if any(v is not None for v in zv.values()) or sensor.time_walk_ps != 0:
        shape = jnp.broadcast_shapes(t.shape, w.shape)
        grid = (sensor.zones_rows, sensor.zones_cols)
        if shape[-3:-1] == grid:
            lead = shape[:-3]
        elif len(shape) >= 2 and shape[-2] == sensor.n_zones:
            lead = shape[:-2]
        else:
            raise UserError(f"sensor {sensor.name} has per-zone terms: give arrivals per zone, shaped (..., "
                            f"{grid[0]}, {grid[1]}, K) or (..., {sensor.n_zones}, K), not {tuple(shape)}")
        flat = lead + (sensor.n_zones, shape[-1])
        t, w = apply_zone_terms_arrivals(jnp.broadcast_to(t, shape).reshape(flat), jnp.broadcast_to(w, shape).reshape(flat),
                                         **zv)
        if xt > 0:  # crosstalk: the zone's gain and offset, no overlap
            xt = xt * (1.0 if zv["gains"] is None else jnp.asarray(zv["gains"], dt)[:, None])
            xt_t = 0.0 if zv["offsets_ps"] is None else jnp.asarray(zv["offsets_ps"], dt)[:, None]
        if sensor.time_walk_ps != 0:  # the zone's light that arrives inside the window
            inside = (t >= sensor.start_offset_ps) & (t < sensor.start_offset_ps + sensor.window_ps)
            flux = sensor.photon_scale * jnp.sum(jnp.where(inside, w, 0.0), axis=-1, keepdims=True) + xt
            shift = walk_shift_ps(flux, sensor.time_walk_ps)
            t, xt_t = t + shift, xt_t + shift
        counts = _expected(sensor, t, w, lights_on, xt, xt_t)
        return counts.reshape(shape[:-1] + (sensor.n_bins,))
    return _expected(sensor, t, w, lights_on, xt, 0.0)


def _expected(sensor: SensorConfig, t, w, lights_on: bool, crosstalk, crosstalk_times_ps):
    dt = t.dtype
    return expected_counts(
        t,
        w,
        edges_ps=jnp.asarray(sensor.bin_edges_ps(), dt),
        sigma_ps=sensor.impulse_sigma_ps,
        photon_scale=sensor.photon_scale,
        iterations=float(sensor.iterations),
        floor_per_bin=floor_per_bin(sensor, lights_on),
        crosstalk=crosstalk,
        crosstalk_times_ps=crosstalk_times_ps,
        pulse=pulse_boxes(sensor),
        pileup=sensor.pileup,
        max_count=sensor.max_count if sensor.saturation else None,
        spads=sensor.spads_per_zone,
        dead_bins=dead_bins(sensor),
    )


def sample_histogram(key, sensor: SensorConfig, times_ps, weights, *, lights_on: bool = True, repeats: int = 1):
    """Noisy histograms: expected counts, then captures drawn by the sensor's noise model (:class:`.noise.CaptureNoise`).

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
    return CaptureNoise.of(sensor).draw(key, mean)


def apply_jitter(histogram, extra_jitter_fwhm_ps, bin_width_ps):
    """Blur existing histograms with Gaussian timing jitter (DENALI's jitter study).

    Each bin is treated as a uniform box of its width and re-binned through a
    Gaussian of the given FWHM, exactly; mass blurred past either end of the
    window is lost, as it would be on the sensor.

    Parameters
    ----------
    histogram : array, shape (..., B)
        Counts or expected counts.
    extra_jitter_fwhm_ps : float
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
    sigma = sigma_of_fwhm(jnp.asarray(extra_jitter_fwhm_ps, dtype))
    return bin_boxes(edges[:-1], bin_width_ps, h, edges, sigma)
