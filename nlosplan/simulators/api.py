"""Simulation API, independent of the backend.

``expected_histogram`` / ``sample`` / ``background_histogram`` /
``explain`` / ``simulate`` take a :class:`~nlosplan.simulators.scene.Scene`
and a :class:`~nlosplan.sensor_models.config.SensorConfig`. The background
follows DENALI's NOOBJECT protocol: the same capture without the hidden
object; the signal is the capture minus the background.

The backend is looked up by name in :data:`BACKENDS` (one
:class:`~nlosplan.simulators.backend.Backend` each: ``fast`` and
``mitsuba``) after the inputs are checked; every backend builds its
:class:`~nlosplan.simulators.result.SimulationResult` the same way.

Examples
--------
>>> from nlosplan.sensor_models import preset
>>> from nlosplan.simulators import denali_scene, expected_histogram
>>> mean = expected_histogram(denali_scene("A", "8in", position=19), preset("tmf8828-3x3-short"))
>>> mean.shape
(3, 3, 128)
"""

from __future__ import annotations

import numpy as np

from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.simulators.backend import Backend
from nlosplan.simulators.fast.backend import FastBackend
from nlosplan.simulators.fast.plan import SimPlan, build_plan
from nlosplan.simulators.mitsuba.backend import TwinBackend
from nlosplan.simulators.result import SimulationResult
from nlosplan.simulators.scene import Scene

__all__ = ["BACKENDS", "background_histogram", "expected_histogram", "explain", "sample", "simulate"]

#: The backends by name ("mitsuba": the Mitsuba 3 twin; Mitsuba itself is imported on its first render).
BACKENDS: dict[str, Backend] = {"fast": FastBackend(), "mitsuba": TwinBackend()}


def _backend(scene: Scene, sensor: SensorConfig, backend: str) -> Backend:
    """The backend asked for, after checking the scene and sensor."""
    if not isinstance(scene, Scene):
        raise UserError(f"scene must be a Scene (e.g. denali_scene(...)), not {type(scene).__name__}")
    if not isinstance(sensor, SensorConfig):
        raise UserError(f"sensor must be a SensorConfig (e.g. preset('tmf8828-3x3-short')), not {type(sensor).__name__}")
    if backend not in BACKENDS:
        raise UserError(f"unknown backend {backend!r}; available: {', '.join(BACKENDS)}")
    return BACKENDS[backend]


def expected_histogram(scene: Scene, sensor: SensorConfig, *, backend: str = "fast", fidelity="default",
                       zones=None, dtype="float32", prune: bool = True) -> np.ndarray:
    """Expected counts of one capture.

    Parameters
    ----------
    scene : Scene
    sensor : SensorConfig
    backend : {"fast", "mitsuba"}
        ``mitsuba``: the Mitsuba 3 + mitransient twin (:mod:`nlosplan.simulators.mitsuba`,
        seed 0; ``dtype`` and ``prune`` do not apply; result float64).
    fidelity : str, dict or Fidelity
        ``draft``, ``low``, ``default``, ``high``, ``reference`` or knobs
        (the twin's knobs for ``mitsuba``: ``spp``, ``zone_sub``, ...).
    zones : list of (row, col), optional
        Only these zones.
    dtype : {"float32", "float64"}
    prune : bool
        Leave out what the scene does not need (the result is the same).

    Returns
    -------
    ndarray, shape (rows, cols, n_bins), or (len(zones), n_bins)
        Expected counts (after pile-up and the 24-bit clip when enabled).
    """
    return _backend(scene, sensor, backend).expected(scene, sensor, fidelity=fidelity, zones=zones, dtype=dtype,
                                                     prune=prune)


def background_histogram(scene: Scene, sensor: SensorConfig, **kw) -> np.ndarray:
    """Expected counts of the same capture without hidden objects (DENALI's NOOBJECT)."""
    return expected_histogram(scene.without_objects(), sensor, **kw)


def sample(scene: Scene, sensor: SensorConfig, rng=0, repeats: int = 1, *, backend: str = "fast",
           fidelity="default", zones=None, dtype="float32", prune: bool = True) -> np.ndarray:
    """Noisy captures: Poisson counts of the expectation, 24-bit clipped.

    Parameters
    ----------
    rng : int or jax random key
        Explicit randomness.
    repeats : int
        Independent captures.
    backend, fidelity, zones, dtype, prune
        As :func:`expected_histogram`.

    Returns
    -------
    ndarray of int64, shape (repeats, rows, cols, n_bins) (or (repeats, zones, n_bins))
    """
    return _backend(scene, sensor, backend).sample(scene, sensor, rng, repeats, fidelity=fidelity, zones=zones,
                                                   dtype=dtype, prune=prune)


def explain(scene: Scene, sensor: SensorConfig, *, fidelity="default", zones=None, prune: bool = True) -> SimPlan:
    """The plan of terms: what is computed for this scene, what is left out, and why.

    Returns
    -------
    SimPlan
        ``str(plan.explain())`` is a table; ``plan.to_dict()`` is JSON-friendly.
    """
    _backend(scene, sensor, "fast")
    return build_plan(scene, sensor, fidelity, zones=zones, prune=prune)


def simulate(scene: Scene, sensor: SensorConfig, *, rng=None, repeats: int = 0, backend: str = "fast",
             fidelity="default", zones=None, dtype="float32", prune: bool = True) -> SimulationResult:
    """Expected capture, its NOOBJECT background, the signal, the parts and optional noisy captures.

    Parameters
    ----------
    rng : int or jax random key, optional
        Seed of the noisy captures (required when ``repeats > 0``).
    repeats : int
        Noisy captures to draw of each (with and without the object).
    Other parameters as :func:`expected_histogram`.
    """
    return _backend(scene, sensor, backend).simulate(scene, sensor, rng=rng, repeats=repeats, fidelity=fidelity,
                                                     zones=zones, dtype=dtype, prune=prune)
