"""Emulate a lower-spec sensor from histograms of a better one.

A design that is coarser than what was captured (or simulated) can be
reached by degrading the histograms: extra Gaussian timing jitter, merged
bins (integer multiples of the captured width), fewer bins (a shorter
window), pooled zones (8x8 -> 4x4 -> 2x2 -> 1x1) and fewer photons
(binomial thinning of counts, scaling of expected counts). A design that is
*finer* than the capture cannot be reached: :func:`reach` says why instead of
extrapolating.

Every operation on expected counts is linear, so the same operator applies to
Jacobians (last axis of the histogram first: ``(..., R, C, B)`` arrays with
a trailing parameter axis are handled by :func:`degrade_linear`).

Notes
-----
Jitter adds in quadrature: a capture with Gaussian jitter FWHM ``j0`` blurred
by ``sqrt(j**2 - j0**2)`` has jitter ``j``. On counts, jitter is emulated
exactly at bin resolution by moving every count independently
(multinomial over the kernel of :func:`jitter_kernel`); on expected counts
by the exact box re-binning of :func:`nlosplan.sensor_models.pipeline.apply_jitter`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosplan.errors import UserError
from nlosplan.sensor_models.impulse import impulse_fwhm_ps, sigma_of_fwhm

__all__ = ["Degradation", "reach", "degrade_expected", "degrade_linear", "degrade_counts", "jitter_kernel",
           "pool_zones", "merge_bins"]


@dataclass(frozen=True)
class Degradation:
    """How to turn a captured sensor's histograms into a design's.

    Parameters
    ----------
    zone_factor : (int, int)
        Captured zones pooled per design zone along rows and columns.
    bin_factor : int
        Captured bins merged per design bin.
    n_bins : int
        Design bins kept after merging (the first ones: a shorter window).
    extra_jitter_fwhm_ps : float
        FWHM of the Gaussian blur added (ps), in quadrature with what the capture had.
    photon_fraction : float
        Fraction of the photons kept (<= 1 for counts; any > 0 for expected counts).
    captured_bin_width_ps : float
    """

    zone_factor: tuple[int, int] = (1, 1)
    bin_factor: int = 1
    n_bins: int = 128
    extra_jitter_fwhm_ps: float = 0.0
    photon_fraction: float = 1.0
    captured_bin_width_ps: float = 100.0

    @property
    def bin_width_ps(self) -> float:
        """The design's bin width, ps."""
        return self.captured_bin_width_ps * self.bin_factor


def reach(captured, design, *, counts: bool = True) -> tuple[Degradation | None, str]:
    """The degradation from a captured sensor to a design, or why there is none.

    Parameters
    ----------
    captured, design : SensorConfig
        What was captured (or simulated) and what to emulate.
    counts : bool
        The captures are photon counts (then more photons than captured cannot be emulated).

    Returns
    -------
    degradation : Degradation or None
    reason : str
        Empty when reachable, else one sentence naming the parameter.
    """
    r0, c0, r1, c1 = captured.zones_rows, captured.zones_cols, design.zones_rows, design.zones_cols
    if r0 % r1 or c0 % c1:
        return None, (f"zones {r1}x{c1} are not a pooling of the captured {r0}x{c0} "
                      "(each axis must divide it)")
    ratio = design.bin_width_ps / captured.bin_width_ps
    factor = round(ratio)
    if factor < 1 or abs(ratio - factor) > 1e-6 * max(1.0, ratio):
        return None, (f"bin width {design.bin_width_ps:g} ps is not a whole multiple of the captured "
                      f"{captured.bin_width_ps:g} ps")
    if abs(design.start_offset_ps - captured.start_offset_ps) > 1e-6 * captured.bin_width_ps:
        return None, "the time offset differs from the capture's (bins cannot be shifted by a fraction)"
    if design.n_bins > captured.n_bins // factor:
        return None, (f"{design.n_bins} bins of {design.bin_width_ps:g} ps need a "
                      f"{design.n_bins * design.bin_width_ps / 1000:.2f} ns window; the capture has "
                      f"{captured.n_bins * captured.bin_width_ps / 1000:.2f} ns")
    j0, j1 = captured.jitter_fwhm_ps, design.jitter_fwhm_ps
    p0, p1 = captured.pulse_fwhm_ps, design.pulse_fwhm_ps
    blur0, blur1 = impulse_fwhm_ps(p0, j0), impulse_fwhm_ps(p1, j1)
    if blur1 < blur0 - 1e-9:
        return None, (f"timing blur {blur1:g} ps FWHM (jitter {j1:g}, pulse {p1:g}) is sharper than the "
                      f"captured {blur0:g} ps")
    photons0 = captured.photon_scale * captured.iterations
    photons1 = design.photon_scale * design.iterations
    if photons0 <= 0:
        return None, "the capture has no photon budget (photon_scale or iterations is 0)"
    fraction = photons1 / photons0
    if counts and fraction > 1 + 1e-9:
        return None, (f"{fraction:.3g}x the captured photon budget cannot be emulated from counts "
                      "(thinning only removes photons)")
    if fraction <= 0:
        return None, "the design has no photon budget"
    extra = math.sqrt(max(blur1 ** 2 - blur0 ** 2, 0.0))
    return Degradation((r0 // r1, c0 // c1), factor, design.n_bins, extra, min(fraction, 1.0) if counts else fraction,
                       captured.bin_width_ps), ""


def pool_zones(h: np.ndarray, factor: tuple[int, int]) -> np.ndarray:
    """Sum blocks of zones: ``(..., R, C, B) -> (..., R/fr, C/fc, B)``."""
    fr, fc = factor
    if fr == fc == 1:
        return h
    *lead, r, c, b = h.shape
    return h.reshape(*lead, r // fr, fr, c // fc, fc, b).sum(axis=(-4, -2))


def merge_bins(h: np.ndarray, factor: int, n_bins: int) -> np.ndarray:
    """Sum groups of ``factor`` bins and keep the first ``n_bins``: ``(..., B) -> (..., n_bins)``."""
    keep = n_bins * factor
    h = h[..., :keep]
    if factor == 1:
        return h
    return h.reshape(*h.shape[:-1], n_bins, factor).sum(axis=-1)


def jitter_kernel(extra_jitter_fwhm_ps: float, bin_width_ps: float, *,
                  cutoff_sigmas: float = 5.0) -> tuple[np.ndarray, int]:
    """Probabilities that a count moves by ``k`` bins under Gaussian jitter.

    A count uniform within its bin, displaced by a Gaussian of FWHM
    ``extra_jitter_fwhm_ps``, lands ``k`` bins away with the probability of the
    box-convolved Gaussian over that bin.

    Returns
    -------
    kernel : ndarray, shape (2K+1,)
        Sums to 1 (the tails beyond ``cutoff_sigmas`` are folded into the ends).
    half : int
        ``K``: the kernel's index ``i`` moves a count by ``i - K`` bins.
    """
    from scipy.special import erf

    sigma = sigma_of_fwhm(extra_jitter_fwhm_ps) / bin_width_ps  # in bins
    if sigma <= 0:
        return np.ones(1), 0
    half = max(1, int(math.ceil(cutoff_sigmas * sigma + 1)))
    k = np.arange(-half, half + 1, dtype=float)

    def cdf_int(x):  # integral of the Gaussian CDF, for the box (uniform start) convolution
        z = x / (sigma * math.sqrt(2.0))
        return x * 0.5 * (1 + erf(z)) + sigma / math.sqrt(2 * math.pi) * np.exp(-z * z)

    # P(shift in [k-1/2, k+1/2]) for a start uniform in [0, 1): box (*) box (*) Gaussian
    p = cdf_int(k + 1) - 2 * cdf_int(k) + cdf_int(k - 1)
    p = np.clip(p, 0.0, None)
    return p / p.sum(), half


def _jitter_expected(h: np.ndarray, extra_jitter_fwhm_ps: float, bin_width_ps: float) -> np.ndarray:
    from nlosplan.sensor_models.pipeline import apply_jitter

    return np.asarray(apply_jitter(np.asarray(h, np.float64), extra_jitter_fwhm_ps, bin_width_ps))


def degrade_expected(mean: np.ndarray, d: Degradation) -> np.ndarray:
    """Expected counts of the design: ``(..., R, C, B) -> (..., R', C', n_bins)``, float64.

    Order: zone pooling, jitter at the captured bin width, bin merging and
    truncation, photon scaling. Mass blurred out of the window is lost, as on
    the sensor.
    """
    h = pool_zones(np.asarray(mean, np.float64), d.zone_factor)
    if d.extra_jitter_fwhm_ps > 0:
        h = _jitter_expected(h, d.extra_jitter_fwhm_ps, d.captured_bin_width_ps)
    return merge_bins(h, d.bin_factor, d.n_bins) * d.photon_fraction


def degrade_linear(arr: np.ndarray, d: Degradation) -> np.ndarray:
    """:func:`degrade_expected` for an array with a trailing parameter axis: ``(..., R, C, B, P)``."""
    moved = np.moveaxis(np.asarray(arr, np.float64), -1, 0)  # (P, ..., R, C, B)
    return np.moveaxis(degrade_expected(moved, d), 0, -1)


def degrade_counts(counts: np.ndarray, d: Degradation, rng) -> np.ndarray:
    """Counts the design would have recorded: ``(..., R, C, B) -> (..., R', C', n_bins)``, int64.

    Zones pooled, every count thinned with probability ``photon_fraction``
    (binomial) and displaced by the extra jitter (multinomial over
    :func:`jitter_kernel`; counts pushed out of the window are lost), bins
    merged and truncated.

    Parameters
    ----------
    counts : array_like of int, shape (..., R, C, B)
    d : Degradation
        With ``photon_fraction <= 1``.
    rng : numpy.random.Generator or int
    """
    rng = np.random.default_rng(rng)
    if d.photon_fraction > 1 + 1e-12:
        raise UserError("counts cannot be given more photons than were captured")
    h = pool_zones(np.asarray(counts, np.int64), d.zone_factor)
    if d.photon_fraction < 1:
        h = rng.binomial(h, d.photon_fraction)
    if d.extra_jitter_fwhm_ps > 0:
        kernel, half = jitter_kernel(d.extra_jitter_fwhm_ps, d.captured_bin_width_ps)
        moved = rng.multinomial(h, kernel)  # (..., B, 2K+1): where each bin's counts go
        b = h.shape[-1]
        out = np.zeros(h.shape[:-1] + (b + 2 * half,), np.int64)
        for i in range(kernel.size):  # shift i - half, padded by half on each side
            out[..., i: i + b] += moved[..., i]
        h = out[..., half: half + b]
    return merge_bins(h, d.bin_factor, d.n_bins)
