"""The calibration workflows behind ``nlosplan calibrate``: plane captures, DENALI folders and capture stores.

Each input kind has two steps, so that the command can check its own
options between them in the order it always has:

1. ``load_*``: read the captures and the sensor to calibrate, and check that
   they fit together (zones, bins, noise against the lights labels).
2. ``calibrate_*``: the matching simulated scenes, the fit (on all captures,
   or on a seeded part with the rest held out and scored) and the
   calibrated sensor, as a :class:`Calibration`.

The command prints and writes what a :class:`Calibration` holds (the sensor
file, the residual plot); bootstrap refits run through
:meth:`Calibration.bootstrap`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from nlosplan.calibration.bootstrap import BootstrapErrors, bootstrap_errors
from nlosplan.calibration.denali import (calibrated_denali_sensor, check_noise, denali_holdout, fit_denali, fit_floors,
                                         pulse_model)
from nlosplan.calibration.denali_data import (DenaliCaptures, check_sensor, denali_capture_set, load_denali_captures,
                                              wall_zones)
from nlosplan.calibration.fit import CalibrationFit, predict
from nlosplan.calibration.model import CaptureSet
from nlosplan.calibration.plane import calibrated_sensor, capture_set, fit_plane, plane_holdout
from nlosplan.calibration.tmf882x_fit import DistanceCaptures, load_distance_captures
from nlosplan.errors import UserError
from nlosplan.sensor_models import SensorConfig, resolve_sensor
from nlosplan.simulators import WallScene, wall_arrivals
from nlosplan.simulators import resolve_fidelity

__all__ = ["Calibration", "calibrate_denali", "calibrate_plane", "load_denali", "load_plane", "plane_arrivals"]


@dataclass(frozen=True, eq=False)
class Calibration:
    """One calibration run: the fit, the calibrated sensor and the captures behind them.

    Attributes
    ----------
    base, sensor : SensorConfig
        The sensor calibrated, and the calibrated one.
    fit : CalibrationFit
    holdout : PlaneHoldout or DenaliHoldout or None
        Held-out scores (None when every capture was fitted).
    captures : CaptureSet
        Every usable capture (those the residual plot shows).
    fit_captures : CaptureSet
        The captures fitted (those a bootstrap resamples).
    zones : list of int
        Flat zone indices fitted.
    pulse, noise : str
        The pulse model and noise mode used.
    inputs : DenaliCaptures or None
        DENALI input (None for plane captures).
    """

    base: SensorConfig
    sensor: SensorConfig
    fit: CalibrationFit
    holdout: object
    captures: CaptureSet
    fit_captures: CaptureSet
    zones: list
    pulse: str
    noise: str
    inputs: DenaliCaptures | None = None
    groups: object = None
    fit_groups: object = None

    def _floors(self, cs: CaptureSet, groups):
        """The ``noise`` argument of :func:`~.fit.predict` (per-folder quiet floors for DENALI input)."""
        return self.noise if self.inputs is None else fit_floors(self.fit, cs, self.noise, groups)

    def bootstrap(self, resamples: int, seed: int, progress: Callable[[int, int], None] | None = None
                  ) -> BootstrapErrors:
        """Bootstrap errors of the fit: ``resamples`` refits on the fitted captures drawn with replacement."""
        return bootstrap_errors(self.fit_captures, self.fit, resamples=resamples, seed=seed,
                                noise=self._floors(self.fit_captures, self.fit_groups), progress=progress)

    def predicted(self) -> np.ndarray:
        """Expected counts of :attr:`captures` under the fit, shape (N, Z, B)."""
        return predict(self.fit, self.captures, self._floors(self.captures, self.groups))


# --------------------------------------------------------------------- plane captures
def load_plane(path, sensor="tmf8828-3x3-short") -> tuple[DistanceCaptures, SensorConfig]:
    """Plane captures at known distances (``tmf882x_distance`` JSON) and the sensor to calibrate.

    Raises
    ------
    UserError
        Unreadable captures, an unknown sensor, or a sensor with another number of zones.
    """
    base = resolve_sensor(sensor)
    captures = load_distance_captures(path)
    n_zones = captures.hists.shape[1]
    if n_zones != base.n_zones:
        raise UserError(f"the captures have {n_zones} zones but sensor {base.name} has {base.n_zones}; "
                        "give a matching --sensor")
    return captures, base


def plane_arrivals(base: SensorConfig, n_zones: int | None = None) -> Callable[[float], tuple[np.ndarray, np.ndarray]]:
    """``arrivals(d)``: times (ps) and weights, each (zones, rays), of a unit-albedo wall square-on at ``d`` metres.

    ``n_zones`` (default the sensor's) rows, zones row-major: the plane captures' fits, scores and
    cross-validation all take their arrivals from here.
    """
    n_zones = base.n_zones if n_zones is None else int(n_zones)

    def arrivals(d):
        t, w = wall_arrivals(WallScene(distance_m=float(d), albedo=1.0), base)
        return t.reshape(n_zones, -1), w.reshape(n_zones, -1)

    return arrivals


def calibrate_plane(captures: DistanceCaptures, base: SensorConfig, *, zones, steps, pulse: str = "shape",
                    noise: str = "measured", min_distance_m: float = 0.06, start: dict | None = None,
                    holdout: float = 0.0, seed: int = 0, lights: str = "on") -> Calibration:
    """Calibrate ``base`` on plane captures (see :func:`~.plane.fit_plane` and :func:`~.plane.plane_holdout`).

    Parameters
    ----------
    captures : DistanceCaptures
    base : SensorConfig
    zones : list of int
        Flat zone indices to fit.
    steps : list of str
        Calibration steps in order (``scale``, ``pulse``, ``noise``).
    pulse : {"shape", "gaussian"}
    noise : {"measured", "global"}
    min_distance_m : float
        Captures closer than this are left out, metres.
    start : dict, optional
        Start values by parameter name.
    holdout : float
        Fraction of captures kept out of the fit and scored (0: fit on all).
    seed : int
        Seed of the holdout split.
    lights : {"on", "off"}
        The captures' room lights: the floor becomes the ambient (on) or dark (off) rate.
    """
    n_zones = captures.hists.shape[1]
    arrivals = plane_arrivals(base, n_zones)
    kw = dict(zones=zones, iterations=base.iterations, steps=steps, pulse=pulse, noise=noise,
              min_distance_m=min_distance_m, start=dict(start or {}))
    held = None
    if holdout > 0:
        fit, held = plane_holdout(captures, arrivals, fit_fraction=1 - holdout, seed=seed, **kw)
    else:
        fit, _ = fit_plane(captures, arrivals, **kw)
    usable = np.flatnonzero(captures.distance_m >= min_distance_m)
    cs_all = capture_set(captures, arrivals, zones, base.iterations, usable)
    floor = float(np.median(cs_all.counts[..., -30:])) if noise == "measured" else None
    sensor = calibrated_sensor(base, fit, floor, lights_on=lights == "on")
    fit_idx = usable if held is None else held.fit_indices
    cs_fit = capture_set(captures, arrivals, zones, base.iterations, fit_idx)
    return Calibration(base, sensor, fit, held, cs_all, cs_fit, list(zones), pulse, noise)


# --------------------------------------------------------------------- DENALI folders and capture stores
def load_denali(path, where: dict | None = None, *, sensor=None, trust_pickle: bool = False,
                fidelity="default", noise: str = "measured") -> tuple[DenaliCaptures, SensorConfig]:
    """DENALI-layout captures (a folder or a capture store) and the sensor to calibrate.

    Parameters
    ----------
    path : str or Path
        A DENALI-layout folder or a capture store (``.sqlite``).
    where : dict, optional
        Label filter (one zone mode at a time).
    sensor : str or SensorConfig, optional
        The sensor to calibrate (default: the one the captures were stored with).
    trust_pickle : bool
        Folder input: allow capture files that need pickle.
    fidelity : str
        Fast-simulator level of the matching scenes (checked here, used by :func:`calibrate_denali`).
    noise : {"measured", "global"}
        Checked against the captures' lights labels.

    Raises
    ------
    UserError
        Unknown fidelity, unreadable input, nothing matches, captures of several sensors with no
        ``sensor`` given, a sensor whose zones or bins differ, or a noise mode the lights do not allow.
    """
    resolve_fidelity(fidelity)
    caps = load_denali_captures(path, where, trust_pickle=trust_pickle)
    if sensor:
        base = resolve_sensor(sensor)
    elif caps.sensor is not None:
        base = caps.sensor
    else:
        raise UserError(f"the captures in {path} were stored with several sensors; give --sensor, or "
                        "filter with --where sensor_hash=...")
    check_sensor(caps, base)
    check_noise(caps.labels["lights"], noise)
    return caps, base


def calibrate_denali(caps: DenaliCaptures, base: SensorConfig, *, steps, zones=None, pulse: str | None = None,
                     noise: str = "measured", start: dict | None = None, holdout: float = 0.0, seed: int = 0,
                     fidelity="default", on_start: Callable[[], None] | None = None) -> Calibration:
    """Calibrate ``base`` on DENALI captures (see :func:`~.denali.fit_denali` and :func:`~.denali.denali_holdout`).

    Parameters
    ----------
    caps : DenaliCaptures
    base : SensorConfig
    steps : list of str
    zones : list of int, optional
        Flat zone indices to fit (default: every zone that sees the relay wall).
    pulse : {"shape", "gaussian"}, optional
        Default: ``shape`` when the sensor has a measured pulse shape, else ``gaussian``.
    noise : {"measured", "global"}
    start : dict, optional
    holdout : float
        Fraction of the gantry positions kept out of the fit and scored.
    seed : int
    fidelity : str
        Fast-simulator level of the matching scenes.
    on_start : callable, optional
        Called once the settings are checked, before the simulation and the fit.
    """
    zones = wall_zones(base, fidelity=fidelity) if zones is None else list(zones)
    pulse = pulse or ("shape" if base.pulse_shape is not None else "gaussian")
    pulse_model(base, pulse)
    if on_start is not None:
        on_start()
    cs = denali_capture_set(caps, base, zones=zones, fidelity=fidelity)
    groups = caps.floor_groups()
    kw = dict(steps=steps, pulse=pulse, noise=noise, start=dict(start or {}))
    held = None
    if holdout > 0:
        fit, held = denali_holdout(cs, caps.positions, base, fit_fraction=1 - holdout, seed=seed, groups=groups,
                                   **kw)
    else:
        fit = fit_denali(cs, base, groups=groups, **kw)
    sensor = calibrated_denali_sensor(base, fit, cs, caps.labels["lights"], noise, groups)
    fit_idx = (np.arange(len(cs.labels)) if held is None
               else np.flatnonzero(np.isin(caps.positions, held.positions_fit)))
    fit_groups = None if groups is None else np.asarray(groups, dtype=str)[fit_idx]
    return Calibration(base, sensor, fit, held, cs, cs.subset(fit_idx), zones, pulse, noise, inputs=caps,
                       groups=groups, fit_groups=fit_groups)
