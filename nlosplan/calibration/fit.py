"""Sim-to-real calibration by nlopt: stacked steps, Fisher uncertainties, robustness checks.

:func:`fit_sensor_model` fits the parameters of :mod:`.model` to real
captures by Poisson maximum likelihood (mean deviance per bin), with nlopt's
BOBYQA on normalized, bounded variables. DENALI's three calibration functions
are steps that stack (``scale`` -> ``pulse`` -> ``noise``): each fits its
own parameters with the earlier ones held at their fitted values; a final
joint pass refines all the selected ones together. Uncertainties are the
square roots of the diagonal of the inverse Fisher information of the
Poisson model at the optimum (parameters it cannot identify are flagged,
never printed as a huge number).

Robustness: saturated zones (a bin at the 24-bit maximum) and zones without
signal are left out with a message; nothing usable, a start outside the
bounds, or a fit that does not lock onto the measured peaks raise
:class:`~nlosplan.errors.UserError` with one line saying why.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.constants import MAX_COUNT_24BIT
from nlosplan.errors import UserError
from nlosplan.calibration.model import PARAM_NAMES, PARAMS, STEPS, CaptureSet, make_model

#: A zone's net peak (counts above its floor) below this is "no signal".
MIN_NET_PEAK = 100.0
#: Bins at the end of a histogram that estimate its noise floor (median).
FLOOR_BINS = 30
#: Median |peak-bin error| above which a fit has not locked onto the data.
MAX_PEAK_ERROR_BINS = 2.0
#: Fisher eigenvalues below this fraction of the largest mark a parameter combination as unidentifiable.
IDENTIFIABLE_RTOL = 1e-10


@dataclass
class CalibrationFit:
    """Result of :func:`fit_sensor_model`; ``to_dict()`` is JSON-ready.

    Attributes
    ----------
    values : dict
        Fitted (or held) value of every parameter, physical units.
    errors : dict
        1-sigma Fisher uncertainty of each fitted parameter, or None when unidentifiable.
    fitted : list of str
        Parameters fitted (the union of the steps).
    steps : list of dict
        Per step: its parameters, deviance before and after, evaluations.
    deviance : float
        Mean Poisson deviance per used bin at the optimum.
    used : ndarray of bool, shape (N, Z)
        Capture zones used.
    messages : list of str
        What was left out and why, parameters at a bound, unidentifiable ones.
    """

    values: dict
    errors: dict
    fitted: list
    steps: list
    deviance: float
    used: np.ndarray
    messages: list = field(default_factory=list)
    pulse_shape: tuple | None = None
    pulse_step_ps: float = 100.0
    pulse_t0_ps: float = 0.0

    def theta(self) -> np.ndarray:
        """Parameters in model order, shape (6,)."""
        return np.array([self.values[n] for n in PARAM_NAMES])

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        return {"values": self.values, "errors": self.errors, "fitted": self.fitted, "steps": self.steps,
                "deviance": self.deviance, "used_zones": int(self.used.sum()), "messages": self.messages,
                "pulse_shape": None if self.pulse_shape is None else list(self.pulse_shape),
                "pulse_step_ps": self.pulse_step_ps, "pulse_t0_ps": self.pulse_t0_ps}


def usable_zones(captures: CaptureSet, *, max_count: int = MAX_COUNT_24BIT, min_net_peak: float = MIN_NET_PEAK):
    """Which capture zones can be fitted, and a message for each left out.

    Returns
    -------
    used : ndarray of bool, shape (N, Z)
    messages : list of str

    Raises
    ------
    UserError
        When no zone of any capture is usable.
    """
    c = np.asarray(captures.counts, dtype=np.float64)
    if c.ndim != 3 or not np.all(np.isfinite(c)) or np.any(c < 0):
        raise UserError("calibration counts must be finite, non-negative, shaped (captures, zones, bins)")
    floor = np.median(c[..., -FLOOR_BINS:], axis=-1)
    net = c.max(-1) - floor
    saturated = c.max(-1) >= max_count
    quiet = net < min_net_peak
    used = ~saturated & ~quiet
    messages = []
    for i, z in zip(*np.nonzero(saturated)):
        messages.append(f"capture {captures.labels[i]} zone {z}: saturated (a bin at {max_count}), left out")
    for i, z in zip(*np.nonzero(quiet & ~saturated)):
        messages.append(f"capture {captures.labels[i]} zone {z}: no signal (net peak {net[i, z]:.0f} counts "
                        f"< {min_net_peak:g}), left out")
    if not used.any():
        raise UserError(f"no capture zone has usable signal: {len(messages)} left out "
                        f"({messages[0] if messages else 'empty input'})")
    return used, messages


def _theta_of_z(z, free, fixed):
    """Physical theta (6,) from normalized free values (traceable)."""
    out = []
    j = 0
    for i, p in enumerate(PARAMS):
        if free[i]:
            zi = z[j]
            j += 1
            if p.log:
                out.append(jnp.exp(np.log(p.lo) + zi * (np.log(p.hi) - np.log(p.lo))))
            else:
                out.append(p.lo + zi * (p.hi - p.lo))
        else:
            out.append(jnp.asarray(fixed[i], jnp.float64))
    return jnp.stack(out)


def _deviance_fn(model, counts, mask, floor):
    """``dev(theta, weights=None)``: mean Poisson deviance per masked bin (``weights``, shaped like the counts,
    replace the mask: e.g. how often each capture was drawn by a bootstrap resample)."""
    n = jnp.asarray(counts, jnp.float64)
    m = jnp.asarray(mask, jnp.float64)
    fl = None if floor is None else jnp.asarray(floor, jnp.float64)

    def dev(theta, weights=None):
        w = m if weights is None else weights
        mu = model(theta)
        if fl is not None:  # measured floor per capture zone instead of the global noise level
            mu = mu - theta[4] + fl
        mu = jnp.maximum(mu, 1e-12)
        d = 2.0 * (mu - n + jnp.where(n > 0, n * jnp.log(jnp.where(n > 0, n, 1.0) / mu), 0.0))
        return jnp.sum(d * w) / jnp.sum(w)

    return dev


def _minimize(dev, free, theta0, max_evals: int, compiled=None):
    """BOBYQA over the normalized free parameters from ``theta0``; ``compiled(z)`` (jitted by the caller, to be
    reused across calls) replaces ``dev`` of the physical parameters."""
    import nlopt

    idx = [i for i in range(len(PARAMS)) if free[i]]
    z0 = np.array([PARAMS[i].to_unit(theta0[i]) for i in idx])
    f = compiled or jax.jit(lambda z: dev(_theta_of_z(z, free, theta0)))
    evals = [0]

    def objective(z, grad):
        evals[0] += 1
        v = float(f(jnp.asarray(z)))
        return v if np.isfinite(v) else 1e300

    opt = nlopt.opt(nlopt.LN_BOBYQA, len(idx))
    opt.set_lower_bounds(np.zeros(len(idx)))
    opt.set_upper_bounds(np.ones(len(idx)))
    opt.set_min_objective(objective)
    opt.set_xtol_rel(1e-7)
    opt.set_ftol_rel(1e-10)
    opt.set_maxeval(int(max_evals))
    opt.set_initial_step(0.02)
    z = opt.optimize(np.clip(z0, 0.0, 1.0))
    theta = np.array(theta0, dtype=np.float64)
    for j, i in enumerate(idx):
        theta[i] = float(PARAMS[i].from_unit(z[j]))
    return theta, float(opt.last_optimum_value()), evals[0]


def _fisher_errors(model, theta, free, mask, floor):
    """1-sigma errors (physical) of the free parameters from the Poisson Fisher matrix; None if unidentifiable."""
    idx = [i for i in range(len(PARAMS)) if free[i]]
    z = jnp.asarray([PARAMS[i].to_unit(theta[i]) for i in idx])

    def mu_of(zz):
        th = _theta_of_z(zz, free, theta)
        mu = model(th)
        if floor is not None:
            mu = mu - th[4] + jnp.asarray(floor)
        return mu

    jac = np.asarray(jax.jacfwd(mu_of)(z)).reshape(-1, len(idx))
    mu = np.maximum(np.asarray(mu_of(z)).ravel(), 1e-12)
    keep = np.asarray(mask).ravel() > 0
    fisher = (jac[keep] / mu[keep, None]).T @ jac[keep]
    evals, evecs = np.linalg.eigh(fisher)
    bad_dirs = evals <= IDENTIFIABLE_RTOL * max(evals.max(), 1e-300)
    cov = evecs[:, ~bad_dirs] @ np.diag(1.0 / evals[~bad_dirs]) @ evecs[:, ~bad_dirs].T
    errors = {}
    for j, i in enumerate(idx):
        p = PARAMS[i]
        unident = bool(np.any(np.abs(evecs[j, bad_dirs]) > 1e-3)) or not np.isfinite(cov[j, j]) or cov[j, j] > 1.0
        if unident:
            errors[p.name] = None
            continue
        dz = np.sqrt(max(cov[j, j], 0.0))
        scale = theta[i] * (np.log(p.hi) - np.log(p.lo)) if p.log else (p.hi - p.lo)
        errors[p.name] = float(dz * scale)
    return errors


def initial_values(captures: CaptureSet, used: np.ndarray, timebase=None) -> dict:
    """A start from the data: time base from leading edges (if given), scale from the sums, floor from the tail."""
    c = np.asarray(captures.counts, dtype=np.float64)
    floor = np.median(c[..., -FLOOR_BINS:], axis=-1)
    net = np.clip(c.sum(-1) - floor * c.shape[-1], 0, None)
    wsum = captures.weights.sum(-1)
    ok = used & (wsum > 0)
    scale = float(np.median(net[ok] / (wsum[ok] * captures.iterations)))
    start = {"photon_scale": float(np.clip(scale, 2e-4, 5e3)), "pulse_fwhm_ps": 150.0,
             "bin_width_ps": 95.0, "start_offset_ps": -1100.0,
             "floor_counts": float(np.clip(np.median(floor[used]), 2e-3, 5e5)), "crosstalk": 1e-5}
    if timebase is not None:
        start.update(bin_width_ps=timebase.bin_width_ps, start_offset_ps=timebase.start_offset_ps)
    return start


def measured_floor_counts(captures: CaptureSet, noise) -> np.ndarray | None:
    """The floor per capture zone, shape (N, Z, 1), that ``noise`` asks for; None for one global level.

    Parameters
    ----------
    captures : CaptureSet
    noise : {"global", "measured"} or array of shape (N, Z)
        ``"measured"``: the median of each zone's last :data:`FLOOR_BINS` bins;
        an array: floors (counts per bin) measured by the caller.

    Raises
    ------
    UserError
        An unknown name, or an array of another shape or with negative or non-finite values.
    """
    if isinstance(noise, str):
        if noise not in ("global", "measured"):
            raise UserError(f"noise={noise!r} is unknown; allowed: global, measured")
        return np.median(captures.counts[..., -FLOOR_BINS:], axis=-1)[..., None] if noise == "measured" else None
    floor = np.asarray(noise, dtype=np.float64)
    if floor.shape != captures.counts.shape[:2] or not np.all(np.isfinite(floor)) or np.any(floor < 0):
        raise UserError(f"noise floors must be finite, >= 0 and shaped (captures, zones) = "
                        f"{captures.counts.shape[:2]}, got shape {floor.shape}")
    return floor[..., None]


def fit_sensor_model(captures: CaptureSet, *, steps=("scale", "pulse", "noise"), start: dict | None = None,
                     pulse_shape=None, pulse_step_ps: float = 100.0, pulse_t0_ps: float = 0.0,
                     noise="global", joint: bool = True, max_evals: int = 600) -> CalibrationFit:
    """Fit the sensor model's calibration parameters (photon scale, pulse, time base, floor, crosstalk) to captures.

    Parameters
    ----------
    captures : CaptureSet
    steps : sequence of {"scale", "pulse", "noise"}
        DENALI's calibration functions, applied in this order (they stack).
    start : dict, optional
        Start values by parameter name (physical units); missing ones come
        from :func:`initial_values`. Values outside the bounds are rejected.
    pulse_shape, pulse_step_ps, pulse_t0_ps
        Non-parametric pulse (see :func:`.model.make_model`); None: Gaussian.
    noise : {"global", "measured"} or array of shape (N, Z)
        One noise floor for every capture (fitted by the ``noise`` step) or
        each capture zone's own floor (median of its last 30 bins, or the
        given floors in counts per bin; not fitted), see :func:`measured_floor_counts`.
    joint : bool
        Refine every selected parameter together after the steps.
    max_evals : int
        Objective evaluations per nlopt run.

    Returns
    -------
    CalibrationFit

    Raises
    ------
    UserError
        Unknown step, start outside the bounds, nothing usable, or a fit
        whose peaks do not match the measured ones (a bad start).
    """
    steps = list(steps)
    bad = [s for s in steps if s not in STEPS]
    if bad or not steps:
        raise UserError(f"unknown calibration step(s) {', '.join(bad) or '(none)'}; allowed: {', '.join(STEPS)}")
    floor = measured_floor_counts(captures, noise)
    used, messages = usable_zones(captures)
    values = initial_values(captures, used)
    for name, v in (start or {}).items():
        if name not in PARAM_NAMES:
            raise UserError(f"unknown calibration parameter {name!r}; allowed: {', '.join(PARAM_NAMES)}")
        PARAMS[PARAM_NAMES.index(name)].check(float(v))
        values[name] = float(v)
    model = make_model(captures, pulse_shape, pulse_step_ps, pulse_t0_ps, values["bin_width_ps"],
                       values["start_offset_ps"])
    mask = np.broadcast_to(used[..., None], captures.counts.shape)
    dev = _deviance_fn(model, captures.counts, mask, floor)
    theta = np.array([values[n] for n in PARAM_NAMES])
    fitted: list[str] = []
    step_log = []
    for step in steps:
        names = [n for n in STEPS[step] if not (floor is not None and n == "floor_counts")]
        free = np.array([n in names for n in PARAM_NAMES])
        before = float(dev(jnp.asarray(theta)))
        theta, after, n_evals = _minimize(dev, free, theta, max_evals)
        step_log.append({"step": step, "parameters": names, "deviance_before": before, "deviance_after": after,
                         "evaluations": n_evals})
        fitted += [n for n in names if n not in fitted]
    free = np.array([n in fitted for n in PARAM_NAMES])
    if joint and len(steps) > 1:
        before = float(dev(jnp.asarray(theta)))
        theta, after, n_evals = _minimize(dev, free, theta, max_evals)
        step_log.append({"step": "joint", "parameters": list(fitted), "deviance_before": before,
                         "deviance_after": after, "evaluations": n_evals})
    result_values = {n: float(v) for n, v in zip(PARAM_NAMES, theta)}
    _check_peaks(model, theta, captures, used, floor)
    for n in fitted:
        p = PARAMS[PARAM_NAMES.index(n)]
        z = p.to_unit(result_values[n])
        if z < 1e-4 or z > 1 - 1e-4:
            messages.append(f"{n} = {result_values[n]:.4g} {p.unit} is at its bound [{p.lo:g}, {p.hi:g}]: "
                            "the data do not constrain it there")
    errors = _fisher_errors(model, theta, free, mask, floor)
    messages += [f"{n} is not identifiable from these captures (flat likelihood direction)"
                 for n, e in errors.items() if e is None]
    return CalibrationFit(result_values, errors, fitted, step_log, float(dev(jnp.asarray(theta))), used, messages,
                          None if pulse_shape is None else tuple(float(v) for v in pulse_shape),
                          float(pulse_step_ps), float(pulse_t0_ps))


def _check_peaks(model, theta, captures, used, floor) -> None:
    mu = np.asarray(model(jnp.asarray(theta)))
    err = np.abs(mu.argmax(-1) - captures.counts.argmax(-1))[used]
    med = float(np.median(err))
    if med > MAX_PEAK_ERROR_BINS:
        raise UserError(f"the fit did not lock onto the measured peaks (median peak-bin error {med:.1f} bins > "
                        f"{MAX_PEAK_ERROR_BINS:g}); the start is probably too far off: give a closer "
                        "bin_width_ps/start_offset_ps start (e.g. from 'nlosplan sensor fit-timebase')")


def predict(fit: CalibrationFit, captures: CaptureSet, noise="global") -> np.ndarray:
    """Expected counts of ``captures`` under the fitted parameters, shape (N, Z, B).

    ``noise`` as in :func:`fit_sensor_model` (a per-zone floor replaces the fitted global level).
    """
    model = make_model(captures, fit.pulse_shape, fit.pulse_step_ps, fit.pulse_t0_ps, fit.values["bin_width_ps"],
                       fit.values["start_offset_ps"])
    mu = np.asarray(model(jnp.asarray(fit.theta())), dtype=np.float64)
    floor = measured_floor_counts(captures, noise)
    if floor is not None:
        mu = mu - fit.values["floor_counts"] + floor
    return mu


@dataclass
class ZoneScores:
    """Errors of a fit's prediction on captures (held out, usually), one entry per usable capture zone.

    Attributes
    ----------
    index : list of [int, int]
        ``[capture, zone]`` of each scored capture zone (zone: position in the capture set's zones).
    captures : list of str
        ``"<capture label> zone <zone>"`` of each.
    peak_bin_error : list of int
        ``argmax(pred) - argmax(meas)``, bins.
    shape_l1 : list of float
        ``sum |a pred_net - meas_net| / sum meas_net`` over the return's support plus 2 bins each
        side, ``a`` matching the net sums (the shape, amplitude apart; net: above the floor, the
        median of the last 30 bins).
    amplitude_ratio : list of float
        Predicted over measured net counts (the photon scale's error).
    peak_bin_error_mean_abs, peak_bin_error_max_abs, shape_l1_mean, shape_l1_max, amplitude_ratio_median
        Summaries of the three lists.
    """

    index: list
    captures: list
    peak_bin_error: list
    shape_l1: list
    amplitude_ratio: list
    peak_bin_error_mean_abs: float
    peak_bin_error_max_abs: int
    shape_l1_mean: float
    shape_l1_max: float
    amplitude_ratio_median: float


def zone_scores(fit: CalibrationFit, cs: CaptureSet, noise="measured") -> ZoneScores:
    """Score a fit on captures (every usable zone, see :func:`usable_zones`); ``noise`` as :func:`predict`.

    Zones whose prediction is zero everywhere above its floor (no simulated light) are not scored.

    Raises
    ------
    UserError
        No capture zone is usable or none can be scored.
    """
    used, _ = usable_zones(cs)
    pred = predict(fit, cs, noise)
    meas = np.asarray(cs.counts, dtype=np.float64)
    floor_m = np.median(meas[..., -FLOOR_BINS:], axis=-1)
    floor_p = np.median(pred[..., -FLOOR_BINS:], axis=-1)
    index, labels, peaks, l1s, amps = [], [], [], [], []
    for i, z in zip(*np.nonzero(used)):
        pn = pred[i, z] - floor_p[i, z]
        mn = meas[i, z] - floor_m[i, z]
        if not pn.max() > 0:
            continue
        support = np.flatnonzero(pn > 1e-3 * pn.max())
        win = slice(max(support[0] - 2, 0), support[-1] + 3)
        a = mn[win].sum() / pn[win].sum()
        index.append([int(i), int(z)])
        labels.append(f"{cs.labels[i]} zone {int(z)}")
        peaks.append(int(pred[i, z].argmax()) - int(meas[i, z].argmax()))
        l1s.append(float(np.abs(a * pn[win] - mn[win]).sum() / mn[win].sum()))
        amps.append(float(1.0 / a))
    if not peaks:
        raise UserError("no capture zone can be scored: the fit predicts no signal in any usable zone")
    err = np.abs(peaks)
    return ZoneScores(index, labels, peaks, l1s, amps, float(err.mean()), int(err.max()), float(np.mean(l1s)),
                      float(np.max(l1s)), float(np.median(amps)))
