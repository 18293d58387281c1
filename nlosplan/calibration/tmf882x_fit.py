"""Measure the TMF882x time base and pulse shape from histograms of a plane.

Data: a flat plane square-on at known one-way distances ``d``
(:func:`load_distance_captures`). Time axis as in
:class:`~nlosplan.sensor_models.config.SensorConfig`: bin ``j`` covers
``[start_offset_ps + j * bin_width_ps, ...)``; time 0 is emission at zero
optical path; a return from ``d`` arrives at ``T = 2 d / c``.

Method
------
1. Time base (:func:`fit_timebase`): per capture, subtract the background
   (median of the last 30 bins) and find the half-maximum leading edge by
   linear interpolation between bin centres (bin ``j`` at ``j + 0.5``, i.e.
   positions in bins from the left edge of bin 0); the long tail does not
   move it. Least squares ``edge = a + b d`` over ``d >= min_distance_m``
   gives ``bin_width_ps = 2 / (c b)``.
2. Convention: the *nominal arrival* of a return is this half-maximum
   leading edge, so ``start_offset_ps = -a * bin_width_ps`` and the pulse
   shape is placed relative to the same point. Only
   ``pulse_shape_t0_ps - start_offset_ps`` enters the model: use the pair.
3. Pulse (:func:`fit_pulse_shape`): a piecewise-constant pulse of step
   ``bin_width_ps`` starting at ``T + t0_ps`` is binned exactly per capture
   (``bin_boxes``) and solved by non-negative least squares against all
   normalised, background-subtracted histograms at once, i.e. the bin box is
   deconvolved (well posed: the captures sample all sub-bin phases).
   Amplitude and background per capture are then refitted by linear least
   squares and the pulse solved again. The sub-bin phase of ``t0_ps`` is
   fitted (grid, then bounded scalar search). Core FWHM: the Gaussian whose
   box integrals best fit the samples at or above 20 % of the peak.
4. Validation (:func:`holdout_report`): fit on a seeded part, predict the
   held-out histograms with ``bin_arrivals`` (amplitude and background by
   linear least squares), report peak-bin errors and normalised L1.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.optimize import curve_fit, minimize_scalar, nnls
from scipy.special import ndtr

from nlosplan.constants import C_M_PER_PS, FWHM_PER_SIGMA
from nlosplan.errors import UserError
from nlosplan.sensor_models.binning import bin_boxes
from nlosplan.sensor_models.pipeline import bin_arrivals

_BG_BINS = 30  # background: median of the last this many bins
_MIN_PEAK_COUNTS = 100.0  # net peak below this: capture unusable
_LEAD_SAMPLES = 3  # pulse samples starting before the nominal arrival


@dataclass(frozen=True)
class DistanceCaptures:
    """Plane captures: ``distance_m`` (N,) one-way metres; ``hists`` (N, Z, B)
    raw counts per zone (3x3 row-major, zone 4 = centre); ``reference`` (N, B)
    on-chip reference channel counts. All float64."""

    distance_m: np.ndarray
    hists: np.ndarray
    reference: np.ndarray


@dataclass(frozen=True)
class TimebaseFit:
    """Result of :func:`fit_timebase`: ``edge_bin = zero_bin + bins_per_m * d``.

    Positions in bins from the left edge of bin 0 (bin centres at ``j + 0.5``);
    ``start_offset_ps = -zero_bin * bin_width_ps`` (nominal arrival = half-max
    leading edge); ``residual_rms_bins`` of the line; ``indices`` used.
    """

    bin_width_ps: float
    bin_width_se_ps: float
    zero_bin: float
    bins_per_m: float
    start_offset_ps: float
    residual_rms_bins: float
    n_used: int
    indices: tuple[int, ...]


@dataclass(frozen=True)
class PulseShapeFit:
    """Result of :func:`fit_pulse_shape`: ``samples`` (P,) sum to 1; sample ``i``
    covers ``[T + t0_ps + i * step_ps, T + t0_ps + (i + 1) * step_ps)`` for the
    nominal arrival ``T`` (ps). ``residual_rms``: of the unit-area histograms."""

    samples: tuple[float, ...]
    step_ps: float
    t0_ps: float
    core_fwhm_ps: float
    residual_rms: float
    n_used: int


def load_distance_captures(path) -> DistanceCaptures:
    """Read a JSON list of ``{dist_to_plane, hists (Z, B), reference_hist (B,)}``.

    Raises
    ------
    UserError
        One line naming the file if it cannot be read or is invalid.
    """
    from nlosplan.schema import loads, read_text

    path = Path(path)
    data = loads(read_text(path, "capture file", max_bytes=2**30), "json", f"capture file {path}")
    if not isinstance(data, list) or not data:
        raise UserError(f"capture file {path} must hold a non-empty JSON list of captures")
    try:
        dist = np.array([float(e["dist_to_plane"]) for e in data], dtype=np.float64)
        hists = np.array([e["hists"] for e in data], dtype=np.float64)
        ref = np.array([e["reference_hist"] for e in data], dtype=np.float64)
    except (KeyError, TypeError, ValueError) as exc:
        msg = f"{type(exc).__name__}: {exc}".splitlines()[0]
        raise UserError(f"capture file {path}: each entry needs dist_to_plane, hists, reference_hist ({msg})") from None
    if hists.ndim != 3 or ref.shape != (hists.shape[0], hists.shape[-1]) or hists.shape[-1] < 2 * _BG_BINS:
        raise UserError(f"capture file {path}: hists must be zones x bins and reference_hist bins, bins >= {2 * _BG_BINS}")
    for name, arr in (("dist_to_plane", dist), ("hists", hists), ("reference_hist", ref)):
        if not np.all(np.isfinite(arr)) or np.any(arr < 0):
            raise UserError(f"capture file {path}: {name} must be finite and non-negative")
    return DistanceCaptures(dist, hists, ref)


def _background(h):
    """Median of the last ``_BG_BINS`` bins, shape (...,)."""
    return np.median(h[..., -_BG_BINS:], axis=-1)


def _leading_edge(h) -> float:
    """Half-max leading edge of (B,) counts, bins from the left edge of bin 0; NaN if no peak."""
    net = h - _background(h)
    k = int(np.argmax(net))
    half = 0.5 * net[k]
    if net[k] < _MIN_PEAK_COUNTS:
        return float("nan")
    j = k
    while j > 0 and net[j - 1] >= half:
        j -= 1
    if j == 0:
        return float("nan")
    return (j - 0.5) + (half - net[j - 1]) / (net[j] - net[j - 1])


def _select(captures, indices, min_distance_m, zone):
    """Indices (optionally restricted) with ``d >= min_distance_m`` and a usable peak."""
    idx = np.arange(captures.distance_m.size) if indices is None else np.asarray(indices, dtype=int)
    idx = idx[captures.distance_m[idx] >= min_distance_m]
    return idx[[np.isfinite(_leading_edge(captures.hists[i, zone])) for i in idx]].astype(int)


def fit_timebase(captures: DistanceCaptures, zone: int = 4, min_distance_m: float = 0.06, indices=None) -> TimebaseFit:
    """Fit bin width and zero-distance bin to the half-max leading edges.

    Parameters
    ----------
    captures : DistanceCaptures
    zone : int
        Zone index (4 = centre of 3x3).
    min_distance_m : float
        Ignore captures closer than this, metres (near-field, crosstalk overlap).
    indices : sequence of int, optional
        Restrict to these captures (default all).

    Returns
    -------
    TimebaseFit
        ``bin_width_se_ps`` is the OLS standard error (statistical only).
    """
    idx = _select(captures, indices, min_distance_m, zone)
    if idx.size < 3:
        raise UserError(f"fit_timebase needs >= 3 usable captures at d >= {min_distance_m} m; got {idx.size}")
    edges = np.array([_leading_edge(captures.hists[i, zone]) for i in idx])
    d = captures.distance_m[idx]
    (a, b), *_ = np.linalg.lstsq(np.stack([np.ones_like(d), d], axis=1), edges, rcond=None)
    resid = edges - (a + b * d)
    se_b = np.sqrt(resid @ resid / max(idx.size - 2, 1) / np.sum((d - d.mean()) ** 2))
    bw = 2.0 / (C_M_PER_PS * b)
    return TimebaseFit(float(bw), float(bw * se_b / b), float(a), float(b), float(-a * bw),
                       float(np.sqrt(np.mean(resid**2))), int(idx.size), tuple(int(i) for i in idx))


def _templates(arrival_ps, t0_ps, step_ps, n_samples, edges_ps):
    """Bin contents of each unit pulse sample per arrival, shape (N, P, B); ``step_ps`` must
    equal the bin width, so sample ``i`` is sample 0 moved by ``i`` bins (exact)."""
    n_bins = edges_ps.size - 1
    ext = edges_ps[0] + step_ps * np.arange(-n_samples, n_bins + 1)  # P extra bins in front
    starts = arrival_ps[:, None] + t0_ps
    first = np.asarray(bin_boxes(starts, step_ps, np.ones_like(starts), ext, 0.0))  # (N, P + B)
    return np.stack([first[:, n_samples - i : n_samples - i + n_bins] for i in range(n_samples)], axis=1)


def _solve_shape(hists, bg, amp, mats):
    """NNLS pulse over all captures (bins in each template's support); (samples, rss, rows)."""
    support = [m.sum(axis=0) > 0 for m in mats]
    rows = np.concatenate([m[:, w].T for m, w in zip(mats, support)])
    rhs = np.concatenate([(h[w] - b0) / a0 for h, b0, a0, w in zip(hists, bg, amp, support)])
    s, rnorm = nnls(rows, rhs, maxiter=5000)
    return s, rnorm**2, rhs.size


def _amp_bg(h, template):
    """Linear least squares ``h ~ amp * template + bg``; returns (amp, bg)."""
    (amp, bg), *_ = np.linalg.lstsq(np.stack([template, np.ones_like(template)], axis=-1), h, rcond=None)
    return float(amp), float(bg)


def _core_fwhm(s, step):
    """FWHM (ps) of the Gaussian whose box integrals fit the samples >= 20 % of the peak."""
    k = int(np.argmax(s))
    lo, hi = k, k
    while lo > 0 and s[lo - 1] >= 0.2 * s[k]:
        lo -= 1
    while hi < s.size - 1 and s[hi + 1] >= 0.2 * s[k]:
        hi += 1
    lo, hi = max(min(lo, k - 1), 0), min(max(hi, k + 1), s.size - 1)
    x, y = np.arange(lo, hi + 1) * step, s[lo : hi + 1]

    def model(x, amp, mu, sig):
        return amp * (ndtr((x + step - mu) / sig) - ndtr((x - mu) / sig))

    bounds = ([0.0, x[0] - step, 1e-3 * step], [np.inf, x[-1] + 2 * step, 10 * step])
    (_, _, sig), _ = curve_fit(model, x, y, p0=(y.sum(), (k + 0.5) * step, 0.5 * step), bounds=bounds)
    return float(FWHM_PER_SIGMA * sig)


def fit_pulse_shape(captures: DistanceCaptures, timebase: TimebaseFit, zone: int = 4, n_samples: int = 32,
                    indices=None, min_distance_m: float = 0.06) -> PulseShapeFit:
    """Non-parametric pulse at bin resolution relative to the nominal arrival.

    Parameters
    ----------
    captures : DistanceCaptures
    timebase : TimebaseFit
        Bin width (= sample step, ps) and start offset.
    zone : int
    n_samples : int
        Samples ``P``; the first ``_LEAD_SAMPLES`` (3) start before the arrival.
    indices : sequence of int, optional
        Captures to use (default all); those with ``d < min_distance_m`` are dropped.
    min_distance_m : float

    Returns
    -------
    PulseShapeFit
        ``samples`` (P,) >= 0, sum 1; ``t0_ps`` in ``[-3, -2] * step_ps``.
    """
    idx = _select(captures, indices, min_distance_m, zone)
    if idx.size < 2:
        raise UserError(f"fit_pulse_shape needs >= 2 usable captures at d >= {min_distance_m} m; got {idx.size}")
    step = timebase.bin_width_ps
    hists = captures.hists[idx, zone]
    edges = timebase.start_offset_ps + step * np.arange(hists.shape[-1] + 1)
    arrival = 2.0 * captures.distance_m[idx] / C_M_PER_PS
    bg = _background(hists)
    amp = np.clip(np.sum(hists - bg[:, None], axis=-1), 1.0, None)

    def t0_of(phase):
        return -(_LEAD_SAMPLES - phase) * step

    def cost(phase):
        return _solve_shape(hists, bg, amp, _templates(arrival, t0_of(phase), step, n_samples, edges))[1]

    for _ in range(2):  # fit phase and shape, then refit amplitude/background and repeat
        grid = np.linspace(0.0, 1.0, 21)
        g = grid[int(np.argmin([cost(p) for p in grid]))]
        res = minimize_scalar(cost, bounds=(max(g - 0.05, 0.0), min(g + 0.05, 1.0)), method="bounded",
                              options={"xatol": 1e-4})
        mats = _templates(arrival, t0_of(res.x), step, n_samples, edges)
        s = _solve_shape(hists, bg, amp, mats)[0]
        for n, (h, m) in enumerate(zip(hists, mats)):
            amp[n], bg[n] = _amp_bg(h, (s / s.sum()) @ m)
    s, rss, n_rows = _solve_shape(hists, bg, amp, mats)
    s = s / s.sum()
    return PulseShapeFit(tuple(float(v) for v in s), float(step), float(t0_of(res.x)), _core_fwhm(s, step),
                         float(np.sqrt(rss / n_rows)), int(idx.size))


def predict_histogram(distance_m: float, hist, timebase: TimebaseFit, pulse: PulseShapeFit):
    """Model ``bg + amp * binned pulse`` of one histogram (B,), amp and bg by least squares.

    Returns
    -------
    pred : ndarray, shape (B,)
    template : ndarray, shape (B,)
        Unit-area pulse at the predicted arrival ``2 d / c``, binned by ``bin_arrivals``.
    bg : float
    """
    edges = timebase.start_offset_ps + timebase.bin_width_ps * np.arange(hist.shape[-1] + 1)
    p = np.asarray(pulse.samples)
    boxes = (pulse.t0_ps + pulse.step_ps * np.arange(p.size), pulse.step_ps, p)
    t = np.array([2.0 * distance_m / C_M_PER_PS])
    template = np.asarray(bin_arrivals(t, np.ones(1), edges, 0.0, boxes))
    amp, bg = _amp_bg(hist, template)
    return bg + amp * template, template, bg


@dataclass
class HoldoutReport:
    """Result of :func:`holdout_report`; ``dataclasses.asdict`` is JSON-ready."""

    n_fit: int
    n_holdout: int
    bin_width_ps: float
    start_offset_ps: float
    pulse_shape_t0_ps: float
    peak_bin_error_mean_abs: float
    peak_bin_error_max_abs: int
    l1_mean: float
    l1_max: float
    holdout_distance_m: list
    holdout_peak_bin_error: list
    holdout_l1: list


def holdout_report(captures: DistanceCaptures, fit_fraction: float = 0.5, seed: int = 0, zone: int = 4,
                   min_distance_m: float = 0.06) -> HoldoutReport:
    """Fit time base and pulse on a seeded random part, score the held-out rest.

    Peak-bin error: ``argmax(pred) - argmax(meas)``, bins. Normalised L1:
    ``sum |pred - meas| / sum (meas - bg)`` over the pulse's support plus 2
    bins each side. Captures unusable for :func:`fit_timebase` are in neither part.
    """
    idx = _select(captures, None, min_distance_m, zone)
    perm = np.random.default_rng(seed).permutation(idx)
    n_fit = int(round(fit_fraction * idx.size))
    fit_idx, test_idx = np.sort(perm[:n_fit]), np.sort(perm[n_fit:])
    if fit_idx.size < 3 or test_idx.size < 1:
        raise UserError(f"holdout needs >= 3 fitting and >= 1 held-out captures; got {fit_idx.size}, {test_idx.size}")
    tb = fit_timebase(captures, zone, min_distance_m, fit_idx)
    pulse = fit_pulse_shape(captures, tb, zone, indices=fit_idx, min_distance_m=min_distance_m)
    errors, l1s = [], []
    for i in test_idx:
        h = captures.hists[i, zone]
        pred, template, bg = predict_histogram(float(captures.distance_m[i]), h, tb, pulse)
        errors.append(int(np.argmax(pred)) - int(np.argmax(h)))
        support = np.flatnonzero(template > 0)
        w = slice(max(support[0] - 2, 0), support[-1] + 3)
        l1s.append(float(np.sum(np.abs(pred[w] - h[w])) / np.sum(h[w] - bg)))
    err = np.abs(errors)
    return HoldoutReport(int(fit_idx.size), int(test_idx.size), tb.bin_width_ps, tb.start_offset_ps, pulse.t0_ps,
                         float(err.mean()), int(err.max()), float(np.mean(l1s)), float(np.max(l1s)),
                         [float(captures.distance_m[i]) for i in test_idx], errors, l1s)
