"""Calibration on DENALI-layout captures: the relay-wall rig at known geometry, the object on the gantry.

This module holds the fit (:func:`fit_denali`: pulse model, start offset
scan, each capture zone's floor from its quiet bins), the holdout split by
gantry position (:func:`denali_holdout`) and the calibrated sensor
(:func:`calibrated_denali_sensor`). Its inputs come from
:mod:`.denali_data`: the captures and the arrivals of their matching
simulated scenes (:func:`~.denali_data.denali_capture_set`).

The gantry position is the unit of the held-out split (:func:`denali_holdout`):
every repeat, object and lights setting at a position is on the same side.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.constants import FWHM_PER_SIGMA
from nlosplan.errors import UserError
from nlosplan.calibration.fit import (
    FLOOR_BINS,
    CalibrationFit,
    ZoneScores,
    fit_sensor_model,
    initial_values,
    usable_zones,
    zone_scores,
)
from nlosplan.calibration.model import PARAM_NAMES, CaptureSet, make_model, poisson_deviance
from nlosplan.calibration.plane import calibrated_sensor
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.impulse import impulse_fwhm_ps

__all__ = ["MIN_QUIET_BINS", "PULSES", "QUIET_COUNTS", "QUIET_SIGMAS", "DenaliHoldout", "calibrated_denali_sensor",
           "check_noise", "denali_holdout", "fit_denali", "fit_floors", "pulse_model", "quiet_floors",
           "split_positions"]

#: Pulse models: the sensor's measured pulse shape broadened by a fitted Gaussian, or a Gaussian alone.
PULSES = ("shape", "gaussian")
#: Half-range (ps) and step (in bins) of the start offset scan.
OFFSET_SCAN_PS = 1500.0
OFFSET_SCAN_STEP = 1.0
#: Captures the offset scan looks at (spread over the set).
OFFSET_SCAN_CAPTURES = 8
#: A bin where the model expects less than this many counts (pulse 3x wider) is quiet, i.e. floor only...
QUIET_COUNTS = 0.01
#: ...unless the crosstalk at time 0 reaches it: the pulse's support widened by this many sigmas each side.
QUIET_SIGMAS = 4.0
#: Fewest quiet bins (over a group's captures) that measure a zone's floor (else the median of its last 30 bins).
MIN_QUIET_BINS = 5


# --------------------------------------------------------------------- fit
def pulse_model(sensor: SensorConfig, pulse: str | None = None) -> tuple:
    """The pulse model of a fit: ``(shape, step_ps, t0_ps, fwhm_start_ps)``.

    Parameters
    ----------
    sensor : SensorConfig
    pulse : {"shape", "gaussian"}, optional
        The sensor's measured pulse shape (``shape`` None for ``"gaussian"``);
        default: the shape when the sensor has one.

    Raises
    ------
    UserError
        An unknown model, or ``"shape"`` for a sensor without a measured pulse.
    """
    if pulse is None:
        pulse = "shape" if sensor.pulse_shape is not None else "gaussian"
    if pulse not in PULSES:
        raise UserError(f"pulse={pulse!r} is unknown; allowed: {', '.join(PULSES)}")
    fwhm = impulse_fwhm_ps(sensor.pulse_fwhm_ps, sensor.jitter_fwhm_ps)
    if pulse == "gaussian":
        return None, 100.0, 0.0, fwhm if fwhm >= 20.0 else 150.0
    if sensor.pulse_shape is None:
        raise UserError(f"sensor {sensor.name} has no measured pulse shape; use --pulse gaussian, or a sensor "
                        "with a pulse shape (e.g. calibrated on plane captures)")
    return sensor.pulse_shape, sensor.pulse_shape_step_ps, sensor.pulse_shape_t0_ps, max(fwhm, 20.0)


def _scan_offset(cs: CaptureSet, used: np.ndarray, start: dict, shape, step, t0, noise: str) -> float:
    """The start offset (ps) that best explains a few captures, on a grid of ``OFFSET_SCAN_STEP`` bins."""
    from nlosplan.calibration.model import PARAMS

    rows = np.flatnonzero(used.any(axis=1))
    rows = rows[np.unique(np.linspace(0, rows.size - 1, min(OFFSET_SCAN_CAPTURES, rows.size)).round().astype(int))]
    sub = cs.subset(rows)
    values = {**initial_values(sub, used[rows]), **start}
    model = make_model(sub, shape, step, t0, values["bin_width_ps"], values["start_offset_ps"])
    off = PARAMS[PARAM_NAMES.index("start_offset_ps")]
    grid = np.arange(values["start_offset_ps"] - OFFSET_SCAN_PS, values["start_offset_ps"] + OFFSET_SCAN_PS,
                     OFFSET_SCAN_STEP * values["bin_width_ps"])
    grid = grid[(grid >= off.lo) & (grid <= off.hi)]
    thetas = np.tile([values[n] for n in PARAM_NAMES], (grid.size, 1))
    thetas[:, PARAM_NAMES.index("start_offset_ps")] = grid
    mu = np.asarray(jax.vmap(model)(jnp.asarray(thetas)), dtype=np.float64)
    if noise == "measured":
        mu = mu - values["floor_counts"] + np.median(sub.counts[..., -FLOOR_BINS:], axis=-1)[..., None]
    mask = np.broadcast_to(used[rows][..., None], sub.counts.shape)
    dev = [poisson_deviance(m, sub.counts, mask) for m in mu]
    return float(grid[int(np.argmin(dev))])


def quiet_floors(cs: CaptureSet, values: dict, pulse_shape=None, pulse_step_ps: float = 100.0,
                 pulse_t0_ps: float = 0.0, groups=None) -> np.ndarray:
    """Each capture zone's floor: the mean count of the quiet bins of its group, shape (N, Z), counts per bin.

    A bin is quiet when the light the model expects there (``values`` with
    the Gaussian pulse three times wider) is below :data:`QUIET_COUNTS` and
    the crosstalk at time 0 cannot reach it (the pulse's support and
    :data:`QUIET_SIGMAS` widened sigmas each side, whatever the crosstalk's
    size). DENALI captures need this rather than the plane path's median of
    the last 30 bins: a hidden object's three-bounce return can fall there.
    The floor (dark counts, ambient light) of a zone is shared by the
    captures of a group, so that a few quiet bins per capture still measure
    it well; a group's zone with fewer than :data:`MIN_QUIET_BINS` quiet
    bins falls back to each capture's median of its last 30 bins.

    Parameters
    ----------
    cs : CaptureSet
    values : dict
        Parameters by name (physical units), e.g. ``fit.values`` or a start.
    pulse_shape, pulse_step_ps, pulse_t0_ps
        As :func:`~nlosplan.calibration.model.make_model`.
    groups : sequence of length N, optional
        Captures sharing a floor, e.g. :meth:`~.denali_data.DenaliCaptures.floor_groups`
        (one DENALI folder: object, size, lights); default: each capture alone.
    """
    from nlosplan.calibration.model import PARAMS

    model = make_model(cs, pulse_shape, pulse_step_ps, pulse_t0_ps, values["bin_width_ps"], values["start_offset_ps"])
    fwhm = min(3.0 * values["pulse_fwhm_ps"], PARAMS[PARAM_NAMES.index("pulse_fwhm_ps")].hi)
    wide = {**values, "floor_counts": 0.0, "crosstalk": 0.0, "pulse_fwhm_ps": fwhm}
    signal = np.asarray(model(jnp.asarray([wide[n] for n in PARAM_NAMES])), dtype=np.float64)
    reach = QUIET_SIGMAS * fwhm / FWHM_PER_SIGMA
    lo, hi = (pulse_t0_ps, pulse_t0_ps + len(pulse_shape) * pulse_step_ps) if pulse_shape is not None else (0.0, 0.0)
    edges = values["start_offset_ps"] + values["bin_width_ps"] * np.arange(cs.counts.shape[-1] + 1)
    crosstalk = (edges[1:] > lo - reach) & (edges[:-1] < hi + reach)
    quiet = (signal < QUIET_COUNTS) & ~crosstalk
    counts = np.asarray(cs.counts, dtype=np.float64)
    _, group = np.unique(np.asarray(range(len(counts)) if groups is None else list(groups), dtype=str),
                         return_inverse=True)
    sums = np.zeros((group.max() + 1, counts.shape[1]))
    n = np.zeros_like(sums)
    np.add.at(sums, group, (counts * quiet).sum(-1))
    np.add.at(n, group, quiet.sum(-1))
    mean = (sums / np.maximum(n, 1))[group]
    return np.where(n[group] >= MIN_QUIET_BINS, mean, np.median(counts[..., -FLOOR_BINS:], axis=-1))


def fit_denali(cs: CaptureSet, sensor: SensorConfig, *, steps=("scale", "pulse", "noise"), pulse: str | None = None,
               noise: str = "measured", start: dict | None = None, scan: bool = True, groups=None) -> CalibrationFit:
    """Calibrate ``sensor`` on DENALI captures (:func:`~.denali_data.denali_capture_set`).

    Parameters
    ----------
    cs : CaptureSet
    sensor : SensorConfig
        Start values: its bin width and offset; its pulse shape with ``pulse="shape"``.
    steps : sequence of {"scale", "pulse", "noise"}
        As :func:`~nlosplan.calibration.fit.fit_sensor_model`.
    noise : {"measured", "global"}
        Each capture zone's own floor (:func:`quiet_floors` under the start
        values; not fitted) or one fitted level.
    groups : sequence of length N, optional
        Captures sharing a floor (see :func:`quiet_floors`).
    pulse : {"shape", "gaussian"}, optional
        The sensor's measured pulse shape broadened by a fitted Gaussian
        (``pulse_fwhm_ps``), or a Gaussian alone (default: the shape when the
        sensor has one).
    start : dict, optional
        Start values by parameter name (override the sensor's and the scan's).
    scan : bool
        Start the offset at the best of a grid (``+-1500 ps`` in one-bin steps)
        on a few captures, unless ``start`` gives it: a sensor whose offset is
        many bins off still locks onto the peaks.

    Returns
    -------
    CalibrationFit
    """
    shape, step, t0, fwhm = pulse_model(sensor, pulse)
    first = {"bin_width_ps": float(np.clip(sensor.bin_width_ps, 50.0, 200.0)),
             "start_offset_ps": float(np.clip(sensor.start_offset_ps, -3000.0, 1000.0)), "pulse_fwhm_ps": fwhm}
    if noise not in ("measured", "global"):
        raise UserError(f"noise={noise!r} is unknown; allowed: measured, global")
    start = dict(start or {})
    used, _ = usable_zones(cs)
    if scan and "start_offset_ps" not in start:
        first["start_offset_ps"] = _scan_offset(cs, used, {**first, **start}, shape, step, t0, noise)
    values = {**initial_values(cs, used), **first, **start}
    floors = quiet_floors(cs, values, shape, step, t0, groups) if noise == "measured" else "global"
    return fit_sensor_model(cs, steps=steps, start={**first, **start}, pulse_shape=shape, pulse_step_ps=step,
                           pulse_t0_ps=t0, noise=floors)


def fit_floors(fit: CalibrationFit, cs: CaptureSet, noise: str = "measured", groups=None):
    """The ``noise`` argument of :func:`~.fit.predict` for ``cs`` under a DENALI fit: quiet floors, or "global"."""
    if noise == "global":
        return "global"
    return quiet_floors(cs, fit.values, fit.pulse_shape, fit.pulse_step_ps, fit.pulse_t0_ps, groups)


# --------------------------------------------------------------------- holdout
@dataclass
class DenaliHoldout:
    """Held-out errors of a DENALI calibration, split by gantry position; ``to_dict()`` is JSON-ready.

    Attributes
    ----------
    n_fit, n_holdout : int
        Captures fitted and held out.
    positions_fit, positions_holdout : list of int
        Gantry positions on each side of the (seeded) split.
    seed : int
    scores : ZoneScores
        Peak-bin error, normalized L1 of the shape and amplitude ratio per held-out capture zone.
    """

    n_fit: int
    n_holdout: int
    positions_fit: list
    positions_holdout: list
    seed: int
    scores: ZoneScores = field(repr=False)

    def to_dict(self) -> dict:
        """JSON-ready dictionary (the scores' fields flattened in)."""
        from dataclasses import asdict

        return {"n_fit": self.n_fit, "n_holdout": self.n_holdout, "positions_fit": self.positions_fit,
                "positions_holdout": self.positions_holdout, "seed": self.seed, **asdict(self.scores)}


def split_positions(positions, fit_fraction: float = 0.5, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """Seeded split of the distinct gantry positions: (fit positions, held-out positions), each sorted."""
    if not 0 < fit_fraction < 1:
        raise UserError(f"fit_fraction={fit_fraction} must be between 0 and 1")
    distinct = np.unique(np.asarray(positions, dtype=int))
    perm = np.random.default_rng(seed).permutation(distinct)
    n_fit = int(round(fit_fraction * distinct.size))
    fit_pos, test_pos = np.sort(perm[:n_fit]), np.sort(perm[n_fit:])
    if fit_pos.size < 1 or test_pos.size < 1:
        raise UserError(f"a holdout split by gantry position needs >= 1 fitting and >= 1 held-out position; "
                        f"{distinct.size} position(s) give {fit_pos.size} and {test_pos.size}")
    return fit_pos, test_pos


def denali_holdout(cs: CaptureSet, positions, sensor: SensorConfig, *, fit_fraction: float = 0.5, seed: int = 0,
                   groups=None, **kw) -> tuple[CalibrationFit, DenaliHoldout]:
    """Fit on a seeded part of the gantry positions, score the captures at the others.

    Parameters
    ----------
    cs : CaptureSet
    positions : array of int, shape (N,)
        Gantry position of each capture.
    sensor : SensorConfig
    fit_fraction : float
        Share of the positions fitted.
    seed : int
    groups : sequence of length N, optional
        Captures sharing a floor (see :func:`quiet_floors`).
    **kw
        As :func:`fit_denali`.
    """
    positions = np.asarray(positions, dtype=int)
    fit_pos, test_pos = split_positions(positions, fit_fraction, seed)
    fit_idx = np.flatnonzero(np.isin(positions, fit_pos))
    test_idx = np.flatnonzero(np.isin(positions, test_pos))
    groups = None if groups is None else np.asarray(groups, dtype=str)
    fit = fit_denali(cs.subset(fit_idx), sensor, groups=None if groups is None else groups[fit_idx], **kw)
    test = cs.subset(test_idx)
    scores = zone_scores(fit, test, fit_floors(fit, test, kw.get("noise", "measured"),
                                               None if groups is None else groups[test_idx]))
    return fit, DenaliHoldout(int(fit_idx.size), int(test_idx.size), fit_pos.tolist(), test_pos.tolist(), int(seed),
                              scores)


# --------------------------------------------------------------------- result
def check_noise(lights, noise: str) -> None:
    """Raise :class:`UserError` when one global floor (``noise="global"``) would serve lights on and off."""
    if noise == "global" and len(set(np.asarray(lights, dtype=str).tolist())) > 1:
        raise UserError("--noise global fits one floor, but the captures mix lights on and off; use --noise "
                        "measured or filter, e.g. --where lights=off")


def calibrated_denali_sensor(base: SensorConfig, fit: CalibrationFit, cs: CaptureSet, lights,
                             noise: str = "measured", groups=None) -> SensorConfig:
    """``base`` with the fitted parameters, its dark and ambient rates from the floors of the captures.

    Parameters
    ----------
    base : SensorConfig
    fit : CalibrationFit
    cs : CaptureSet
        The captures whose floors (:func:`quiet_floors` under the fit) set the rates.
    lights : sequence of {"on", "off"}, length N
        Room lights of each capture.
    noise : {"measured", "global"}
        ``global``: the fitted ``floor_counts`` (the captures must share one lights setting).
    groups : sequence of length N, optional
        Captures sharing a floor (see :func:`quiet_floors`).

    Returns
    -------
    SensorConfig
        Lights-off floor -> ``dark_rate_hz``; lights-on floor minus the dark
        floor -> ``ambient_rate_hz`` (the base's dark rate when no capture is
        lights-off).
    """
    check_noise(lights, noise)
    lights = np.asarray(lights, dtype=str)
    kinds = sorted(set(lights.tolist()))
    if noise == "global":
        return calibrated_sensor(base, fit, None, lights_on=kinds[0] == "on")
    used, _ = usable_zones(cs)
    floor = fit_floors(fit, cs, groups=groups)

    def level(kind: str) -> float:
        pick = used & (lights == kind)[:, None]
        return float(np.median(floor[pick] if pick.any() else floor[lights == kind]))

    if "off" not in kinds:
        return calibrated_sensor(base, fit, level("on"), lights_on=True)
    if "on" not in kinds:
        return calibrated_sensor(base, fit, level("off"), lights_on=False)
    dark = level("off") / (base.iterations * fit.values["bin_width_ps"] * 1e-12) if base.iterations else 0.0
    return calibrated_sensor(base.replace(dark_rate_hz=dark), fit, level("on"), lights_on=True)

