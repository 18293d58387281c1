"""Fit every zone of plane captures: per-zone terms, amplitude law, pile-up, pulse and tail.

:func:`fit_plane_zones` fits the model of :mod:`.plane_model` by Poisson
maximum likelihood (mean deviance per bin) with nlopt's L-BFGS on
normalized, bounded variables and exact JAX gradients, in three stacked
steps from data-driven starts (amplitude, timing, then everything with the
pulse samples). Starts come from the fitting captures only:

- time base: half-maximum leading edges of the reference zone
  (:func:`~nlosplan.calibration.tmf882x_fit.fit_timebase`);
- iterations ``N`` (pile-up): the ambient floor after a return is shadowed by
  ``exp(-Lambda)`` while the return takes ``1 - exp(-Lambda)`` of the
  iterations, so ``N = net / (1 - floor_after / floor_before)``;
- pulse: non-negative least squares on the pile-up-corrected histograms
  (:func:`~nlosplan.calibration.tmf882x_fit.fit_pulse_shape`);
- gains and overlap: per zone, ``log(signal / weight) = log(s g_z) + log O_z(d)``
  by least squares on the pile-up-corrected signal.

:func:`zone_sensor` turns a fit into a :class:`SensorConfig` that every
command (and :mod:`.plane_scores`) can use.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.errors import UserError
from nlosplan.calibration.plane_model import (TERMS, PlaneData, blocks, canonical, check_terms,
                                                            first_return_bin, make_plane_model, pack, unpack)
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.noise import rate_hz
from nlosplan.sensor_models.counts import coates_correction
from nlosplan.calibration.tmf882x_fit import DistanceCaptures, fit_pulse_shape, fit_timebase

#: Bins at the end of a histogram used for the floor after the return (start values only).
LATE_BINS = 30
#: A zone's net peak below this many counts is "no signal"; a bin at the 24-bit maximum is saturated.
MIN_NET_PEAK = 100.0
#: Objective evaluations per step.
MAX_EVALS = (200, 400, 4000)
#: Relative change of the mean deviance per L-BFGS iteration that ends a step.
FTOL = 1e-8


@dataclass
class ZoneFit:
    """Result of :func:`fit_plane_zones`; ``to_dict()`` is JSON-ready.

    Attributes
    ----------
    values : dict
        Fitted physical values (see :func:`.plane_model.canonical`); per-zone lists
        follow ``zones``.
    terms : list of str
    zones : list of int
    deviance : float
        Mean Poisson deviance per used bin at the optimum.
    evaluations : int
    converged : bool
        False when the last step stopped at its evaluation budget.
    messages : list of str
    pulse_t0_ps : float
        Left edge of the first pulse sample relative to the arrival, ps (at the fitted bin width).
    n_captures : int
    distances_m : list of float
        The fitted captures' distances.
    seconds : float
    """

    values: dict
    terms: list
    zones: list
    deviance: float
    evaluations: int
    converged: bool
    messages: list = field(default_factory=list)
    pulse_t0_ps: float = 0.0
    n_captures: int = 0
    distances_m: list = field(default_factory=list)
    seconds: float = 0.0

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        return {"values": self.values, "terms": self.terms, "zones": self.zones, "deviance": self.deviance,
                "evaluations": self.evaluations, "converged": self.converged, "messages": self.messages,
                "pulse_t0_ps": self.pulse_t0_ps, "n_captures": self.n_captures, "distances_m": self.distances_m,
                "seconds": self.seconds}


def floor_bins(base: SensorConfig) -> int:
    """How many leading bins hold no return light (at least 4 needed), from the sensor's time base and pulse."""
    t0 = base.pulse_shape_t0_ps if base.pulse_shape is not None else -3.0 * base.bin_width_ps
    n = first_return_bin(base, t0)
    if n < 4:
        raise UserError(f"sensor {base.name}: only {max(n, 0)} bins before the zero-distance return (start_offset_ps "
                        f"{base.start_offset_ps:g}); the floor needs at least 4")
    return min(n, base.n_bins // 4)


def plane_data(captures: DistanceCaptures, arrivals, zones, indices, n_floor: int) -> PlaneData:
    """Captures ``indices`` of ``zones`` with their arrivals and measured floors."""
    idx = np.asarray(indices, dtype=int)
    t, w = zip(*(arrivals(float(captures.distance_m[i])) for i in idx))
    zones = list(zones)
    counts = captures.hists[idx][:, zones]
    return PlaneData(captures.distance_m[idx], counts, np.stack(t)[:, zones], np.stack(w)[:, zones],
                     counts[..., :n_floor].mean(-1), tuple(zones), tuple(f"{captures.distance_m[i]:.3f} m" for i in idx))


def usable(data: PlaneData, max_count: int) -> tuple[np.ndarray, list[str]]:
    """Capture zones to fit (not saturated, with a return), and a message for each left out."""
    c = data.counts
    net = c.max(-1) - data.floor
    sat = c.max(-1) >= max_count
    quiet = net < MIN_NET_PEAK
    msgs = [f"capture {data.labels[i]} zone {data.zones[z]}: saturated, left out" for i, z in zip(*np.nonzero(sat))]
    msgs += [f"capture {data.labels[i]} zone {data.zones[z]}: no signal (net peak {net[i, z]:.0f} counts), left out"
             for i, z in zip(*np.nonzero(quiet & ~sat))]
    used = ~sat & ~quiet
    if not used.any():
        raise UserError("no capture zone has usable signal at these distances")
    return used, msgs


def shadow_iterations(data: PlaneData, used: np.ndarray) -> float | None:
    """Iterations from the ambient shadow behind strong returns (None when no capture zone shows one)."""
    late = np.median(data.counts[..., -LATE_BINS:], axis=-1)
    net = data.counts.sum(-1) - data.floor * data.counts.shape[-1]
    ratio = late / np.maximum(data.floor, 1e-9)
    ok = used & (data.floor > 20) & (ratio < 0.9) & (ratio > 0.05) & (net > 0)
    if ok.sum() < 3:
        return None
    return float(np.median(net[ok] / (1.0 - ratio[ok])))


def _amplitude_starts(data, used, lam, terms) -> dict:
    """Photon scale, gains and overlap distances from corrected signal over arrival weights."""
    from scipy.optimize import least_squares

    d = data.distance_m
    wsum = data.weights.sum(-1)
    ratio = lam / np.maximum(wsum, 1e-300)
    ok = used & (lam > 0) & (wsum > 0)
    z = data.counts.shape[1]
    level, d0 = np.ones(z), np.full(z, 1e-3)
    for j in range(z):
        m = ok[:, j]
        if m.sum() < 2:
            level[j] = float(np.median(ratio[ok])) if ok.any() else 1.0
            continue
        y = np.log(ratio[m, j])
        if "overlap" in terms and m.sum() >= 3:
            def res(p, y=y, dd=d[m]):
                return y - p[0] - np.log(dd**2 / (dd**2 + np.exp(2 * p[1])))
            p = least_squares(res, [float(y.max()), np.log(0.03)], bounds=([-50, np.log(1e-4)], [50, 0.0])).x
            level[j], d0[j] = np.exp(p[0]), np.exp(p[1])
        else:
            level[j] = float(np.exp(np.median(y)))
    out = {"zone_overlap_m2": np.clip(d0, 0.0, 0.19) ** 2}
    if "gains" in terms:
        s = float(np.exp(np.mean(np.log(level))))
        out.update(photon_scale=s, zone_gains=np.clip(level / s, 1.1e-3, 900.0))
    else:
        out.update(photon_scale=float(np.exp(np.median(np.log(level)))), zone_gains=np.ones(z))
    return out


def _minimize(fn, z0: np.ndarray, free: np.ndarray, max_evals: int):
    """Bounded L-BFGS (scipy's L-BFGS-B) on the ``free`` coordinates of ``z`` in [0, 1].

    Returns ``(z, value, evaluations, hit_budget)``; ``hit_budget`` is True when
    the evaluation budget ended the run before a convergence test did.
    """
    from scipy.optimize import minimize

    idx = np.flatnonzero(free)
    z = np.array(z0, dtype=np.float64)
    vg = jax.jit(jax.value_and_grad(fn))

    def objective(x):
        zz = z.copy()
        zz[idx] = x
        v, g = vg(jnp.asarray(zz))
        v = float(v)
        if not np.isfinite(v):
            return 1e300, np.zeros_like(x)
        return v, np.nan_to_num(np.asarray(g, dtype=np.float64)[idx])

    res = minimize(objective, np.clip(z[idx], 0.0, 1.0), jac=True, method="L-BFGS-B",
                   bounds=[(0.0, 1.0)] * idx.size,
                   options={"maxiter": int(max_evals), "maxfun": int(max_evals), "ftol": FTOL, "gtol": 1e-8})
    z[idx] = res.x
    hit = res.status == 1  # iteration or evaluation budget
    return z, float(res.fun), int(res.nfev), hit


def fit_plane_zones(captures: DistanceCaptures, arrivals, base: SensorConfig, *, zones=None, terms=TERMS,
                    indices=None, min_distance_m: float = 0.06, n_pulse: int = 32,
                    max_evals=MAX_EVALS) -> ZoneFit:
    """Fit the all-zone plane model to captures at ``d >= min_distance_m`` among ``indices``.

    Parameters
    ----------
    captures : DistanceCaptures
    arrivals : callable
        ``arrivals(distance_m) -> (times_ps (Z_all, K), weights (Z_all, K))``, zones row-major.
    base : SensorConfig
        The sensor being calibrated (its time base and pulse position size the floor bins).
    zones : sequence of int, optional
        Flat zone indices to fit (default all).
    terms : iterable of str
        Physics terms to fit (default all of :data:`.plane_model.TERMS`).
    n_pulse : int
        Free pulse samples.
    max_evals : tuple of 3 int
        Evaluations of the amplitude, timing and joint steps.

    Returns
    -------
    ZoneFit

    Raises
    ------
    UserError
        Fewer than 3 usable captures, or no usable zone.
    """
    t_start = time.perf_counter()
    terms = check_terms(terms)
    zones = list(range(captures.hists.shape[1])) if zones is None else list(zones)
    idx = np.arange(captures.distance_m.size) if indices is None else np.asarray(indices, dtype=int)
    idx = np.sort(idx[captures.distance_m[idx] >= min_distance_m])
    if idx.size < 3:
        raise UserError(f"calibration needs >= 3 captures at d >= {min_distance_m} m; got {idx.size}")
    n_floor = floor_bins(base)
    data = plane_data(captures, arrivals, zones, idx, n_floor)
    used, messages = usable(data, base.max_count)
    ref = zones[int(np.argmax(used.sum(0) + 1e-3 * data.counts.max(-1).sum(0) / data.counts.max()))]
    tb = fit_timebase(captures, ref, min_distance_m, idx)
    iters = float(base.iterations)
    if "pileup" in terms:
        est = shadow_iterations(data, used)
        if est is None:
            messages.append("no capture shows the ambient shadow of pile-up: iterations start at the sensor's")
        iters = float(np.clip(est if est is not None else iters, 2e4, 5e8))
    hists = captures.hists.astype(np.float64)
    if "pileup" in terms:
        lam_all = np.nan_to_num(np.asarray(coates_correction(hists, iters)), posinf=0.0)
        hists = iters * np.clip(lam_all, 0.0, 1.0)  # linear photons x N, saturated bins dropped
    corrected = DistanceCaptures(captures.distance_m, hists, captures.reference)
    ps = fit_pulse_shape(corrected, tb, ref, n_samples=n_pulse, indices=idx, min_distance_m=min_distance_m)
    lam = (hists[idx][:, zones] - data.floor[..., None]).sum(-1) / iters
    start = _amplitude_starts(data, used, lam, terms)
    values = {"bin_width_ps": tb.bin_width_ps, "start_offset_ps": tb.start_offset_ps,
              "pulse": np.maximum(np.asarray(ps.samples), 1e-7), "zone_time_offsets_ps": np.zeros(len(zones)),
              "zone_time_scales": np.ones(len(zones)), "iterations": iters, "pulse_tail_fraction": 3e-4,
              "pulse_tail_decay_ps": 2500.0, "time_walk_ps": 0.0, **start}
    fixed = {"iterations": iters}
    bl = blocks(terms, len(zones), n_pulse)
    model = make_plane_model(data, terms, fixed, n_pulse=n_pulse, pulse_t0_ps=ps.t0_ps,
                             nominal_bin_width_ps=tb.bin_width_ps, nominal_offset_ps=tb.start_offset_ps)
    n = jnp.asarray(data.counts)
    mask = jnp.asarray(np.broadcast_to(used[..., None], data.counts.shape), jnp.float64)

    def deviance(zv):
        mu = jnp.maximum(model(unpack(bl, zv)), 1e-9)
        dev = 2.0 * (mu - n + jnp.where(n > 0, n * jnp.log(jnp.where(n > 0, n, 1.0) / mu), 0.0))
        return jnp.sum(dev * mask) / jnp.sum(mask)

    z = pack(bl, values)
    names = [b.name for b in bl for _ in range(b.n)]
    amp = {"zone_gains", "photon_scale", "zone_overlap_m2", "iterations", "pulse"}
    timing = {"bin_width_ps", "start_offset_ps", "zone_time_offsets_ps", "zone_time_scales", "time_walk_ps"}
    evals, hit = 0, False
    for step, group in enumerate((timing, amp, None)):
        free = np.array([group is None or nm in group for nm in names])
        if not free.any():
            continue
        z, dev, n_ev, hit = _minimize(deviance, z, free, max_evals[step])
        evals += n_ev
    converged = not hit
    if not converged:
        messages.append(f"the fit did not converge within {max_evals[-1]} evaluations of its joint step; best mean "
                        f"deviance {dev:.4g}")
    phys = {k: np.asarray(v) for k, v in unpack(bl, jnp.asarray(z)).items()}
    vals = canonical(phys)
    vals.setdefault("iterations", float(iters))
    for b in bl:
        v = np.atleast_1d(b.to_unit(np.asarray(phys[b.name])))
        if b.name != "pulse" and np.any(((v < 1e-4) & (b.lo > 0)) | (v > 1 - 1e-4)):
            messages.append(f"{b.name} reached a bound [{b.lo:g}, {b.hi:g}] {b.unit}: the data do not constrain it there")
    scale_t = vals["bin_width_ps"] / tb.bin_width_ps
    if "tail" in terms:
        vals["pulse_tail_decay_ps"] *= scale_t  # fitted on the nominal time axis
    return ZoneFit(vals, terms, zones, float(dev), evals, converged, messages, float(ps.t0_ps * scale_t),
                   int(idx.size), [float(v) for v in data.distance_m], time.perf_counter() - t_start)


def zone_sensor(base: SensorConfig, fit: ZoneFit, *, floor_counts: float | None = None) -> SensorConfig:
    """``base`` with the fitted values: per-zone terms (neutral for zones not fitted), pulse, pile-up, tail.

    ``floor_counts`` (counts per bin, lights on) becomes the ambient rate on top of the base's dark rate.
    """
    v = fit.values
    nz = base.n_zones
    changes = {"bin_width_ps": v["bin_width_ps"], "start_offset_ps": v["start_offset_ps"],
               "photon_scale": v["photon_scale"], "pulse_shape": tuple(v["pulse"]),
               "pulse_shape_step_ps": v["bin_width_ps"], "pulse_shape_t0_ps": fit.pulse_t0_ps, "pulse_fwhm_ps": 0.0,
               "jitter_fwhm_ps": 0.0, "crosstalk": 0.0}

    def per_zone(key, neutral):
        out = [neutral] * nz
        for z, x in zip(fit.zones, v[key]):
            out[z] = float(x)
        return tuple(out)

    if "offsets" in fit.terms:
        changes["zone_time_offsets_ps"] = per_zone("zone_time_offsets_ps", 0.0)
    if "scales" in fit.terms:
        changes["zone_time_scales"] = per_zone("zone_time_scales", 1.0)
    if "gains" in fit.terms:
        changes["zone_gains"] = per_zone("zone_gains", 1.0)
    if "overlap" in fit.terms:
        changes["zone_overlap_m"] = per_zone("zone_overlap_m", 0.0)
    changes["pileup"] = "pileup" in fit.terms
    changes["iterations"] = int(round(v["iterations"])) if "pileup" in fit.terms else base.iterations
    if "tail" in fit.terms:
        changes.update(pulse_tail_fraction=v["pulse_tail_fraction"], pulse_tail_decay_ps=v["pulse_tail_decay_ps"])
    else:
        changes["pulse_tail_fraction"] = 0.0
    changes["time_walk_ps"] = v["time_walk_ps"] if "walk" in fit.terms else 0.0
    if floor_counts is not None:
        rate = rate_hz(floor_counts, changes["iterations"], v["bin_width_ps"])
        changes["ambient_rate_hz"] = max(rate - base.dark_rate_hz, 0.0)
    return base.replace(name=f"{base.name}-calibrated", **changes)
