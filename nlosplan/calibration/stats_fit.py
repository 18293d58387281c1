"""Fit a sensor and scene parameters to a statistics file (``nlosplan calibrate --stats``).

The objective is the sum of squared residuals of every row statistic of the
sensor's zone mode, each divided by the file's ``fit_scales`` (relative for
totals and spreads, absolute for centroids and skews), plus the level
constraints and the nuisances' Gaussian priors. Simulated captures use common
random numbers (:class:`~.stats_model.Noise`, one seed), so the objective is a
smooth function of the parameters; nlopt (BOBYQA, then Nelder-Mead, then
BOBYQA again from the best point) works on variables normalized to [0, 1]
(logarithmic for the photon scale and the floor).

Uncertainty: a bootstrap over the SEMs and the Monte-Carlo noise: each refit
sees the real statistics redrawn within their SEMs and a new noise seed.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from nlosplan.calibration.stats_file import STATISTICS, StatsFile
from nlosplan.calibration.stats_model import NUISANCE_PARAMS, SCENE_PARAMS, SENSOR_PARAMS, Noise, simulate_rows
from nlosplan.errors import UserError

#: Bounds of the sensor and scene parameters: (lo, hi, logarithmic).
BOUNDS = {"photon_scale": (1e-3, 10.0, True), "dark_rate_hz": (1e2, 1e8, True), "ambient_rate_hz": (0.0, 5e6, False),
          "albedo": (0.0, 1.0, False), "diffuse_albedo": (0.0, 1.0, False), "mount_albedo": (0.0, 1.0, False)}
FITTABLE = SENSOR_PARAMS + ("albedo", "diffuse_albedo", "mount_albedo") + NUISANCE_PARAMS
#: What ``calibrate --stats`` fits by default (the findings' best model: diffuse base and mount albedo fixed).
DEFAULT_FREE = ("photon_scale", "dark_rate_hz", "albedo") + NUISANCE_PARAMS


@dataclass
class StatsFit:
    """Result of :func:`fit_stats`: the parameters (sensor fields, scene keywords, nuisances) and the objective."""

    values: dict
    free: tuple
    objective: float
    converged: bool
    evaluations: int
    seconds: float
    message: str = ""
    samples: list = field(default_factory=list)


def bounds(stats: StatsFile, name: str) -> tuple:
    """(lo, hi, log) of a fittable parameter (nuisances: the file's bounds)."""
    if name in BOUNDS:
        return BOUNDS[name]
    base = "background_offset" if name.startswith("background_offset") else name
    if base not in stats.nuisances:
        raise UserError(f"the statistics file declares no nuisance {base}; it cannot be fitted")
    lo, hi = stats.nuisances[base].bounds
    return lo, hi, False


def _to_unit(b, v):
    lo, hi, lg = b
    return float(np.log(v / lo) / np.log(hi / lo)) if lg else (v - lo) / (hi - lo)


def _from_unit(b, u):
    lo, hi, lg = b
    u = float(np.clip(u, 0.0, 1.0))
    return lo * (hi / lo) ** u if lg else lo + u * (hi - lo)


def objective_terms(stats: StatsFile, rows: dict, levels: dict, nuis: dict) -> np.ndarray:
    """Scaled residuals: 4 per row, one per level, one per nuisance prior."""
    sc = stats.fit_scales
    res = []
    for key, m in rows.items():
        r = stats.row(key).values
        res += [(m[0] / r["total"][0] - 1) / sc["total_rel"], (m[1] - r["centroid"][0]) / sc["centroid_bins"],
                (m[2] / r["spread"][0] - 1) / sc["spread_rel"], (m[3] - r["skew"][0]) / sc["skew"]]
    for lev in stats.levels:
        if lev.name in levels:
            v = levels[lev.name]
            res.append((v / lev.value - 1) / sc["level_mean_rel"] if lev.statistic == "mean_count"
                       else (v - lev.value) / sc["level_log_mean"])
    for name, v in nuis.items():
        base = "background_offset" if name.startswith("background_offset") else name
        if base in stats.nuisances:
            mu, sd = stats.nuisances[base].prior
            res.append((v - mu) / sd)
    return np.array(res)


def split(values: dict, sensor):
    """(sensor with the sensor fields of ``values``, scene dict, nuisance dict)."""
    s = sensor.replace(**{k: float(values[k]) for k in SENSOR_PARAMS if k in values})
    return s, {k: values[k] for k in SCENE_PARAMS}, {k: values[k] for k in NUISANCE_PARAMS}


def fit_stats(stats: StatsFile, comp, sensor, start: dict, free=DEFAULT_FREE, *, seed: int = 0,
              maxeval: int = 400) -> StatsFit:
    """Fit the ``free`` parameters (from ``start``: scene and nuisance values; the sensor's own fields).

    Parameters
    ----------
    stats : StatsFile
    comp : Components
        Of ``sensor``'s time base (:func:`~.stats_model.components`).
    sensor : SensorConfig
    start : dict
        :data:`SCENE_PARAMS` and :data:`NUISANCE_PARAMS` values (sensor fields default to ``sensor``'s).
    free : sequence of str
        Names in :data:`FITTABLE`.
    seed : int
        Common-random-number seed.
    maxeval : int
        Evaluations per optimizer pass (three passes).
    """
    import nlopt

    bad = [n for n in free if n not in FITTABLE]
    if bad or not free:
        raise UserError(f"cannot fit {', '.join(bad) or '(nothing)'}; fittable: {', '.join(FITTABLE)}")
    values = {k: float(getattr(sensor, k)) for k in SENSOR_PARAMS} | dict(start)
    bnds = [bounds(stats, n) for n in free]
    noise = Noise(seed)
    count = [0]

    def params(x):
        v = dict(values)
        v.update({n: _from_unit(b, u) for n, b, u in zip(free, bnds, x)})
        return v

    def f(x, grad=None):
        count[0] += 1
        v = params(x)
        s, scene, nuis = split(v, sensor)
        out = simulate_rows(comp, s, scene, nuis, stats, noise)
        over = max(0.0, v["albedo"] + v["diffuse_albedo"] - 1.0)
        return float(np.sum(objective_terms(stats, out["rows"], out["levels"], nuis) ** 2) + 1e4 * over**2)

    t0 = time.perf_counter()
    x0 = np.clip([_to_unit(b, values[n]) for n, b in zip(free, bnds)], 1e-6, 1 - 1e-6)
    best, converged, message = (f(x0), x0), False, ""
    for algo in (nlopt.LN_BOBYQA, nlopt.LN_NELDERMEAD, nlopt.LN_BOBYQA):
        opt = nlopt.opt(algo, len(free))
        opt.set_lower_bounds(np.zeros(len(free)))
        opt.set_upper_bounds(np.ones(len(free)))
        opt.set_min_objective(f)
        opt.set_maxeval(maxeval)
        opt.set_xtol_rel(1e-5)
        opt.set_initial_step(0.05)
        try:
            x = opt.optimize(np.clip(best[1], 1e-6, 1 - 1e-6))
            code = opt.last_optimize_result()
        except nlopt.RoundoffLimited:
            x, code = best[1], nlopt.ROUNDOFF_LIMITED
        v = f(x)
        if v <= best[0]:
            best = (v, x)
        converged = code != nlopt.MAXEVAL_REACHED
        if not converged:
            message = f"stopped at its evaluation budget ({maxeval} per pass); best objective {best[0]:.4g}"
    return StatsFit(values=params(best[1]), free=tuple(free), objective=best[0], converged=converged,
                    evaluations=count[0], seconds=time.perf_counter() - t0, message=message)


def resampled(stats: StatsFile, rng) -> StatsFile:
    """``stats`` with every row statistic redrawn from N(mean, SEM)."""
    rows = tuple(replace(r, values={s: (float(r.values[s][0] + r.values[s][1] * rng.standard_normal()),
                                        r.values[s][1]) for s in STATISTICS}) for r in stats.rows)
    return replace(stats, rows=rows)


def bootstrap(stats: StatsFile, comp, sensor, fit: StatsFit, n: int, *, seed: int = 0, maxeval: int = 150,
              progress=None) -> list[dict]:
    """``n`` refits from ``fit``'s values, each on statistics redrawn within their SEMs and a new noise seed."""
    rng = np.random.default_rng(seed)
    out = []
    start = {k: v for k, v in fit.values.items() if k not in SENSOR_PARAMS}
    base = sensor.replace(**{k: float(fit.values[k]) for k in SENSOR_PARAMS})
    for i in range(n):
        r = fit_stats(resampled(stats, rng), comp, base, start, fit.free, seed=seed + 1000 + i, maxeval=maxeval)
        out.append({k: float(r.values[k]) for k in fit.free})
        if progress is not None:
            progress(i + 1, n)
    return out


def intervals(fit: StatsFit, samples: list[dict]) -> dict:
    """Per fitted name, and per other name that at least two samples hold (a scene parameter the model variants
    fix, :mod:`.stats_variants`): value, std (of the refits), lo and hi (their 2.5 and 97.5 % points, widened to
    hold the value).

    Empty without at least two refits: a single fit carries no spread.
    """
    if len(samples) < 2:
        return {}
    extra = sorted({k for s in samples for k in s} - set(fit.free))
    out = {}
    for k in tuple(fit.free) + tuple(extra):
        v = float(fit.values[k])
        xs = np.array([s[k] for s in samples if k in s], float)
        if len(xs) < 2:
            continue
        out[k] = {"value": v, "std": float(xs.std(ddof=1)), "lo": min(v, float(np.percentile(xs, 2.5))),
                  "hi": max(v, float(np.percentile(xs, 97.5)))}
    return out


def uncertainty_dict(sensor_name: str, fit: StatsFit, samples: list[dict]) -> dict | None:
    """The parameter-uncertainty JSON of the sensor fields fitted (CONTRACT of issue 16,
    :mod:`nlosplan.sensor_models.uncertainty`'s format): ``{"sensor", "parameters", "samples"}``.

    Scene parameters and protocol nuisances are not sensor fields: their intervals go to the scene table
    (:func:`intervals`). None when no sensor field was fitted or there are fewer than two refits.
    """
    iv = intervals(fit, samples)
    names = [k for k in fit.free if k in SENSOR_PARAMS and k in iv]
    if not names:
        return None
    return {"sensor": sensor_name, "parameters": {k: iv[k] for k in names},
            "samples": [{k: float(s[k]) for k in names} for s in samples]}
