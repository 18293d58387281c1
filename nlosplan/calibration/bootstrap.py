"""Bootstrap uncertainties of a calibration: refit on captures resampled with replacement.

The Fisher errors of :func:`~.fit.fit_sensor_model` are statistical only:
they assume the model is right and count photons. On real captures the
model is not exactly right (pile-up, near field, a pulse shape fitted on
the same data), and the spread of the fitted values over resampled
*captures* shows it. A resample with replacement is a weight per capture
(how often it was drawn), so every refit reuses the same jitted model:
the deviance is weighted by the draw counts, and the refit starts from the
full fit and refines all its parameters together (the ``joint`` pass).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.errors import UserError
from nlosplan.calibration.fit import (
    CalibrationFit,
    _deviance_fn,
    _minimize,
    _theta_of_z,
    measured_floor_counts,
)
from nlosplan.calibration.model import PARAM_NAMES, CaptureSet, make_model

#: Fewest resamples that give a meaningful spread.
MIN_RESAMPLES = 5


@dataclass(frozen=True)
class BootstrapErrors:
    """Spread of the fitted parameters over resampled captures; ``to_dict()`` is JSON-ready.

    Attributes
    ----------
    errors : dict
        Standard deviation of each fitted parameter over the resamples, physical units.
    intervals : dict
        Central 95 % interval ``(lo, hi)`` of each fitted parameter, physical units.
    resamples : int
        Refits that finished.
    seed : int
        Seed of the resampling.
    """

    errors: dict
    intervals: dict
    resamples: int
    seed: int

    def to_dict(self) -> dict:
        """JSON-ready dictionary."""
        return {"errors": self.errors, "intervals": {k: list(v) for k, v in self.intervals.items()},
                "resamples": self.resamples, "seed": self.seed}


def bootstrap_errors(captures: CaptureSet, fit: CalibrationFit, *, resamples: int = 30, seed: int = 0,
                     noise="global", max_evals: int = 400, progress=None) -> BootstrapErrors:
    """Refit ``fit`` on ``resamples`` bootstrap resamples of ``captures``.

    Parameters
    ----------
    captures : CaptureSet
        The captures ``fit`` was fitted on (N captures).
    fit : CalibrationFit
        The full fit: its values start every refit, its ``fitted`` parameters are refitted.
    resamples : int
        Bootstrap resamples (>= 5).
    seed : int
        Seed of the resampling.
    noise : {"global", "measured"} or array of shape (N, Z)
        As in :func:`~.fit.fit_sensor_model` (the fit's own setting).
    max_evals : int
        Objective evaluations per refit.
    progress : callable, optional
        ``progress(done, total)`` after each refit.

    Returns
    -------
    BootstrapErrors

    Raises
    ------
    UserError
        Fewer than 5 resamples, or fewer than 2 captures to resample.
    """
    if resamples < MIN_RESAMPLES:
        raise UserError(f"bootstrap resamples {resamples} < {MIN_RESAMPLES}: give at least {MIN_RESAMPLES} "
                        "(30 or more for a 95 % interval)")
    n = captures.counts.shape[0]
    usable = np.flatnonzero(fit.used.any(axis=1))
    if usable.size < 2:
        raise UserError(f"bootstrap needs at least 2 captures with usable zones; this fit has {usable.size}")
    model = make_model(captures, fit.pulse_shape, fit.pulse_step_ps, fit.pulse_t0_ps, fit.values["bin_width_ps"],
                       fit.values["start_offset_ps"])
    floor = measured_floor_counts(captures, noise)
    free = np.array([name in fit.fitted for name in PARAM_NAMES])
    theta0 = fit.theta()
    dev = _deviance_fn(model, captures.counts, np.broadcast_to(fit.used[..., None], captures.counts.shape), floor)
    # one compiled objective for every resample: the draw counts are an argument, not a constant
    weighted = jax.jit(lambda z, w: dev(_theta_of_z(z, free, theta0), w))
    rng = np.random.default_rng(seed)
    rows = []
    for b in range(resamples):
        draws = np.bincount(rng.choice(usable, size=usable.size, replace=True), minlength=n).astype(np.float64)
        w = jnp.asarray(np.broadcast_to((fit.used * draws[:, None])[..., None], captures.counts.shape))
        theta, _, _ = _minimize(dev, free, theta0, max_evals, compiled=lambda z, w=w: weighted(jnp.asarray(z), w))
        rows.append(theta)
        if progress is not None:
            progress(b + 1, resamples)
    values = np.array(rows)
    errors, intervals = {}, {}
    for i, name in enumerate(PARAM_NAMES):
        if free[i]:
            errors[name] = float(np.std(values[:, i], ddof=1))
            lo, hi = np.percentile(values[:, i], [2.5, 97.5])
            intervals[name] = (float(lo), float(hi))
    return BootstrapErrors(errors, intervals, len(rows), int(seed))
