"""Calibration on captures of a flat plane at known distances (``tmf882x_distance`` JSON).

The matching simulated scene of each capture is the plane square-on at its
distance; its arrivals come from the caller (``arrivals(distance_m) ->
(times_ps (Z, K), weights (Z, K))``, e.g. :func:`nlosplan.simulators.wall_arrivals`),
so this module stays on the sensor side. Start values come from the fitting
part only: the time base from half-maximum leading edges
(:func:`~nlosplan.calibration.tmf882x_fit.fit_timebase`) and, with
``pulse="shape"``, the non-parametric pulse
(:func:`~nlosplan.calibration.tmf882x_fit.fit_pulse_shape`).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass, field

import numpy as np

from nlosplan.errors import UserError
from nlosplan.calibration.fit import CalibrationFit, fit_sensor_model, usable_zones, zone_scores
from nlosplan.calibration.model import CaptureSet
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.noise import rate_hz
from nlosplan.calibration.tmf882x_fit import DistanceCaptures, fit_pulse_shape, fit_timebase

PULSES = ("shape", "gaussian")


def capture_set(captures: DistanceCaptures, arrivals, zones, iterations: int, indices=None) -> CaptureSet:
    """Real plane histograms of ``zones`` with their simulated arrivals.

    Parameters
    ----------
    captures : DistanceCaptures
    arrivals : callable
        ``arrivals(distance_m) -> (times_ps (Z_all, K), weights (Z_all, K))``, zones row-major.
    zones : list of int
        Flat zone indices to fit.
    iterations : int
    indices : sequence of int, optional
        Captures to include (default all).
    """
    idx = np.arange(captures.distance_m.size) if indices is None else np.asarray(indices, dtype=int)
    t, w = zip(*(arrivals(float(captures.distance_m[i])) for i in idx))
    t = np.stack(t)[:, zones]
    w = np.stack(w)[:, zones]
    return CaptureSet(captures.hists[idx][:, zones], t, w, int(iterations),
                      tuple(f"{captures.distance_m[i]:.3f} m" for i in idx))


def fit_plane(captures: DistanceCaptures, arrivals, *, zones=(4,), iterations: int = 550_000, indices=None,
              steps=("scale", "pulse", "noise"), pulse: str = "shape", noise: str = "measured",
              min_distance_m: float = 0.06, start: dict | None = None) -> tuple[CalibrationFit, CaptureSet]:
    """Calibrate on plane captures (those at ``d >= min_distance_m`` among ``indices``).

    Returns
    -------
    CalibrationFit, CaptureSet
        The fit and the captures it used.
    """
    if pulse not in PULSES:
        raise UserError(f"pulse={pulse!r} is unknown; allowed: {', '.join(PULSES)}")
    idx = np.arange(captures.distance_m.size) if indices is None else np.asarray(indices, dtype=int)
    idx = idx[captures.distance_m[idx] >= min_distance_m]
    if idx.size < 3:
        raise UserError(f"calibration needs >= 3 captures at d >= {min_distance_m} m; got {idx.size}")
    zones = list(zones)
    cs = capture_set(captures, arrivals, zones, iterations, idx)
    used, _ = usable_zones(cs)
    ref_zone = zones[int(np.argmax(used.sum(0)))]
    tb = fit_timebase(captures, ref_zone, min_distance_m, idx)
    first = {"bin_width_ps": tb.bin_width_ps, "start_offset_ps": tb.start_offset_ps}
    shape = None
    step = tb.bin_width_ps
    t0 = 0.0
    if pulse == "shape":
        ps = fit_pulse_shape(captures, tb, ref_zone, indices=idx, min_distance_m=min_distance_m)
        shape, step, t0 = ps.samples, ps.step_ps, ps.t0_ps
        first["pulse_fwhm_ps"] = 20.0  # the shape already holds the pulse; the Gaussian only broadens it
    fit = fit_sensor_model(cs, steps=steps, start={**first, **(start or {})}, pulse_shape=shape, pulse_step_ps=step,
                          pulse_t0_ps=t0, noise=noise)
    return fit, cs


@dataclass
class PlaneHoldout:
    """Held-out errors of a plane calibration; ``asdict`` is JSON-ready.

    ``peak_bin_error``: ``argmax(pred) - argmax(meas)`` per held-out capture zone (bins).
    ``shape_l1``: ``sum |a pred_net - meas_net| / sum meas_net`` over the return's support plus
    2 bins each side, ``a`` matching the net sums (the shape, amplitude apart).
    ``amplitude_ratio``: predicted over measured net counts (the photon scale's error).
    ``fit_indices``: the captures the fit used (indices into the loaded captures).
    """

    n_fit: int
    n_holdout: int
    distances_m: list
    peak_bin_error: list
    shape_l1: list
    amplitude_ratio: list
    peak_bin_error_mean_abs: float
    peak_bin_error_max_abs: int
    shape_l1_mean: float
    shape_l1_max: float
    amplitude_ratio_median: float
    fit_indices: list = field(default_factory=list)


def holdout_scores(fit: CalibrationFit, cs: CaptureSet, distances, noise: str = "measured") -> PlaneHoldout:
    """Score a fit on held-out captures (every usable zone, :func:`~.fit.zone_scores`)."""
    s = zone_scores(fit, cs, noise)
    dists = [float(distances[i]) for i, _ in s.index]
    return PlaneHoldout(0, len(s.peak_bin_error), dists, s.peak_bin_error, s.shape_l1, s.amplitude_ratio,
                        s.peak_bin_error_mean_abs, s.peak_bin_error_max_abs, s.shape_l1_mean, s.shape_l1_max,
                        s.amplitude_ratio_median)


def plane_holdout(captures: DistanceCaptures, arrivals, *, fit_fraction: float = 0.5, seed: int = 0,
                  **kw) -> tuple[CalibrationFit, PlaneHoldout]:
    """Fit on a seeded part of the captures at ``d >= min_distance_m``, score the rest."""
    min_d = kw.get("min_distance_m", 0.06)
    idx = np.flatnonzero(captures.distance_m >= min_d)
    if not 0 < fit_fraction < 1:
        raise UserError(f"fit_fraction={fit_fraction} must be between 0 and 1")
    perm = np.random.default_rng(seed).permutation(idx)
    n_fit = int(round(fit_fraction * idx.size))
    fit_idx, test_idx = np.sort(perm[:n_fit]), np.sort(perm[n_fit:])
    if fit_idx.size < 3 or test_idx.size < 1:
        raise UserError(f"holdout needs >= 3 fitting and >= 1 held-out captures; got {fit_idx.size}, {test_idx.size}")
    fit, cs_fit = fit_plane(captures, arrivals, indices=fit_idx, **kw)
    zones = list(kw.get("zones", (4,)))
    cs_test = capture_set(captures, arrivals, zones, cs_fit.iterations, test_idx)
    scores = holdout_scores(fit, cs_test, captures.distance_m[test_idx], kw.get("noise", "measured"))
    scores.n_fit = int(fit_idx.size)
    scores.fit_indices = [int(i) for i in fit_idx]
    return fit, scores


def calibrated_sensor(base: SensorConfig, fit: CalibrationFit, floor_counts: float | None = None,
                      lights_on: bool = True) -> SensorConfig:
    """``base`` with the fitted parameters: a sensor file every other command can use.

    The noise floor (counts per bin; the fitted global level, or the median
    measured floor) becomes ``ambient_rate_hz`` (lights on, dark rate kept)
    or ``dark_rate_hz`` (lights off).
    """
    v = fit.values
    floor = v["floor_counts"] if floor_counts is None else float(floor_counts)
    rate = rate_hz(floor, base.iterations, v["bin_width_ps"]) if base.iterations else 0.0
    changes = {"photon_scale": v["photon_scale"], "bin_width_ps": v["bin_width_ps"],
               "start_offset_ps": v["start_offset_ps"], "crosstalk": v["crosstalk"],
               "pulse_fwhm_ps": v["pulse_fwhm_ps"], "pulse_shape": fit.pulse_shape}
    if fit.pulse_shape is not None:
        changes.update(pulse_shape_step_ps=fit.pulse_step_ps, pulse_shape_t0_ps=fit.pulse_t0_ps)
    if lights_on:
        changes["ambient_rate_hz"] = max(rate - base.dark_rate_hz, 0.0)
    else:
        changes["dark_rate_hz"] = rate
    errs = ", ".join(f"{k} {v[k]:.4g} +- {e:.2g}" for k, e in fit.errors.items() if e is not None)
    return base.replace(name=f"{base.name}-calibrated", notes=f"{base.notes} Calibrated by nlosplan calibrate: {errs}.",
                        **changes)


def holdout_dict(h: PlaneHoldout) -> dict:
    """JSON-ready dictionary of :class:`PlaneHoldout`."""
    return asdict(h)
