"""Calibration parameters, their normalization, and the forward model of a capture.

The forward model is the sensor pipeline of
:func:`~nlosplan.sensor_models.pipeline.expected_counts` applied to the
arrivals of each capture's matching simulated scene (``times_ps``,
``weights``, per capture and zone, computed once by the caller):

    mu_j = N * [ s * sum_k w_k IRF_j(t_k) + x * IRF_j(0) ] + b

with ``N`` iterations, ``s`` the photon scale, ``x`` the crosstalk peak at
zero optical path, ``b`` the noise floor (ambient + dark counts per bin) and
``IRF`` the impulse response (the non-parametric pulse shape, if any,
convolved with a Gaussian of ``pulse_fwhm_ps``) on bins of
``bin_width_ps`` starting at ``start_offset_ps``.

Every optimizer works on normalized variables ``z in [0, 1]``: linear or
logarithmic maps of each parameter's bounds, so ps, counts and photons per
iteration are equally scaled.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.impulse import sigma_of_fwhm
from nlosplan.sensor_models.pipeline import pulse_boxes
from nlosplan.sensor_models.transient import TimeGrid, deposit, irf_extent_ps, irf_matrix


@dataclass(frozen=True)
class Param:
    """One fitted parameter: name, unit, bounds and scale of its normalization."""

    name: str
    unit: str
    lo: float
    hi: float
    log: bool = False

    def to_unit(self, value: float) -> float:
        """Physical value -> normalized ``[0, 1]``."""
        if self.log:
            return (math.log(value) - math.log(self.lo)) / (math.log(self.hi) - math.log(self.lo))
        return (value - self.lo) / (self.hi - self.lo)

    def from_unit(self, z):
        """Normalized -> physical (works on arrays)."""
        if self.log:
            return np.exp(np.log(self.lo) + z * (np.log(self.hi) - np.log(self.lo)))
        return self.lo + z * (self.hi - self.lo)

    def check(self, value: float) -> None:
        """Raise :class:`UserError` when ``value`` is outside the bounds."""
        if not (math.isfinite(value) and self.lo <= value <= self.hi):
            raise UserError(f"start value {self.name}={value:g} {self.unit} is outside its bounds "
                            f"[{self.lo:g}, {self.hi:g}]; give a start inside them")


#: Parameters in model order.
PARAMS: tuple[Param, ...] = (
    Param("photon_scale", "photons/iteration per unit weight", 1e-4, 1e4, log=True),
    Param("pulse_fwhm_ps", "ps", 1.0, 2000.0, log=True),
    Param("bin_width_ps", "ps", 50.0, 200.0),
    Param("start_offset_ps", "ps", -3000.0, 1000.0),
    Param("floor_counts", "counts/bin", 1e-3, 1e6, log=True),
    Param("crosstalk", "photons/iteration", 1e-7, 10.0, log=True),
)
PARAM_NAMES = tuple(p.name for p in PARAMS)

#: DENALI's three calibration functions and the parameters each fits (they stack in the order given).
STEPS: dict[str, tuple[str, ...]] = {
    "scale": ("photon_scale",),
    "pulse": ("pulse_fwhm_ps", "bin_width_ps", "start_offset_ps"),
    "noise": ("floor_counts", "crosstalk"),
}


@dataclass(frozen=True)
class CaptureSet:
    """Real histograms with the arrivals of their matching simulated scenes.

    Attributes
    ----------
    counts : ndarray, shape (N, Z, B)
        Measured counts of N captures, Z zones each.
    times_ps, weights : ndarray, shape (N, Z, K)
        Arrival times (ps) and transport weights of each capture's simulated scene.
    iterations : int
        Laser iterations per histogram.
    labels : tuple of str
        One label per capture (e.g. ``"0.150 m"``), for messages and reports.
    """

    counts: np.ndarray
    times_ps: np.ndarray
    weights: np.ndarray
    iterations: int
    labels: tuple

    def subset(self, idx) -> "CaptureSet":
        """The captures at ``idx``."""
        idx = np.asarray(idx, dtype=int)
        return CaptureSet(self.counts[idx], self.times_ps[idx], self.weights[idx], self.iterations,
                          tuple(self.labels[i] for i in idx))


def make_model(captures: CaptureSet, pulse_shape=None, pulse_step_ps: float = 100.0, pulse_t0_ps: float = 0.0,
               nominal_bin_width_ps: float = 92.0, nominal_offset_ps: float = -1100.0, oversample: int = 8):
    """A jitted ``f(theta (6,)) -> mu (N, Z, B)`` of physical parameters in :data:`PARAMS` order.

    Arrivals are deposited on a node grid of ``oversample`` nodes per bin and
    binned through the impulse response by one node-to-bin matrix
    (:mod:`~nlosplan.sensor_models.transient`, as the fast simulator): exact in
    mass and mean time, traceable in the bin width, offset and pulse width.

    Parameters
    ----------
    captures : CaptureSet
    pulse_shape : sequence of float, optional
        Non-parametric pulse (sums to 1), sample ``i`` over
        ``[t0 + i step, t0 + (i + 1) step)`` relative to the nominal arrival;
        the Gaussian of ``pulse_fwhm_ps`` broadens it. None: Gaussian only.
    nominal_bin_width_ps, nominal_offset_ps : float
        Time base that sizes the node grid (the start of the fit).
    """
    n, z, k = captures.times_ps.shape
    n_bins = captures.counts.shape[-1]
    iters = float(captures.iterations)
    shape = None if pulse_shape is None else tuple(float(v) for v in pulse_shape)
    nominal = SensorConfig(n_bins=n_bins, bin_width_ps=float(nominal_bin_width_ps),
                           start_offset_ps=float(nominal_offset_ps), pulse_shape=shape,
                           pulse_shape_step_ps=float(pulse_step_ps), pulse_shape_t0_ps=float(pulse_t0_ps),
                           pulse_fwhm_ps=0.0, iterations=int(captures.iterations))
    sigma_max = sigma_of_fwhm(_param("pulse_fwhm_ps").hi)
    grid = TimeGrid.for_sensor(nominal, 0.0, 1e12, oversample=int(oversample), sigma_ps=sigma_max)
    extent = irf_extent_ps(nominal, sigma_max)
    pulse = pulse_boxes(nominal)
    if pulse is not None:
        pulse = (jnp.asarray(pulse[0]), pulse[1], jnp.asarray(pulse[2]))
    t = jnp.asarray(captures.times_ps, jnp.float64).reshape(-1)
    w = jnp.asarray(captures.weights, jnp.float64).reshape(-1)
    rows = jnp.asarray(np.repeat(np.arange(n * z), k), jnp.int32)
    zero_rows = jnp.arange(n * z, dtype=jnp.int32)

    def model(theta):
        scale, fwhm, bw, t0, noise, xt = (theta[i] for i in range(6))
        nodes = deposit(grid, t, scale * w, rows, n * z, bin_width_ps=bw, start_offset_ps=t0)
        nodes = nodes + deposit(grid, jnp.zeros(n * z), jnp.full(n * z, 1.0) * xt, zero_rows, n * z,
                                bin_width_ps=bw, start_offset_ps=t0)
        mat = irf_matrix(grid, bin_width_ps=bw, sigma_ps=sigma_of_fwhm(fwhm), pulse=pulse, extent_ps=extent,
                         nominal_bin_width_ps=float(nominal_bin_width_ps))
        return (iters * (nodes @ mat) + noise).reshape(n, z, n_bins)

    return jax.jit(model)


def _param(name: str) -> Param:
    return PARAMS[PARAM_NAMES.index(name)]


def poisson_deviance(mu, counts, mask=None) -> float:
    """Mean Poisson deviance per bin ``2 [mu - n + n log(n / mu)]`` over the masked bins."""
    mu = np.maximum(np.asarray(mu, dtype=np.float64), 1e-12)
    n = np.asarray(counts, dtype=np.float64)
    d = 2.0 * (mu - n + np.where(n > 0, n * np.log(np.where(n > 0, n, 1.0) / mu), 0.0))
    if mask is not None:
        d = d[mask]
    return float(np.mean(d))
