"""Simulation API, independent of the backend.

``expected_histogram`` / ``sample`` / ``background_histogram`` /
``explain`` / ``simulate`` take a :class:`~nlosplan.simulators.scene.Scene`
and a :class:`~nlosplan.sensor_models.config.SensorConfig`. The background
follows DENALI's NOOBJECT protocol: the same capture without the hidden
object; the signal is the capture minus the background.

Examples
--------
>>> from nlosplan.sensor_models import preset
>>> from nlosplan.simulators import denali_scene, expected_histogram
>>> mean = expected_histogram(denali_scene("A", "8in", position=19), preset("tmf8828-3x3-short"))
>>> mean.shape
(3, 3, 128)
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import numpy as np

from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.simulators.fast.plan import SimPlan, build_plan
from nlosplan.simulators.fast.simulator import FastSimulator
from nlosplan.simulators.scene import NLOSWarning, Scene

#: Backends that can be asked for by name ("mitsuba": the Mitsuba 3 twin, imported only when asked for).
BACKENDS = ("fast", "mitsuba")


def _check(scene: Scene, sensor: SensorConfig, backend: str) -> None:
    if not isinstance(scene, Scene):
        raise UserError(f"scene must be a Scene (e.g. denali_scene(...)), not {type(scene).__name__}")
    if not isinstance(sensor, SensorConfig):
        raise UserError(f"sensor must be a SensorConfig (e.g. preset('tmf8828-3x3-short')), not {type(sensor).__name__}")
    if backend not in BACKENDS:
        raise UserError(f"unknown backend {backend!r}; available: {', '.join(BACKENDS)}")


def _simulator(scene, sensor, backend, **kw) -> FastSimulator:
    _check(scene, sensor, backend)
    sim = FastSimulator(scene, sensor, **kw)
    for w in sim.plan.warnings:
        warnings.warn(w, NLOSWarning, stacklevel=3)
    return sim


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
    if backend == "mitsuba":
        _check(scene, sensor, backend)
        from nlosplan.simulators.mitsuba.backend import expected as twin_expected

        return twin_expected(scene, sensor, fidelity=fidelity, zones=zones)
    return _simulator(scene, sensor, backend, fidelity=fidelity, zones=zones, dtype=dtype, prune=prune).expected()


def background_histogram(scene: Scene, sensor: SensorConfig, **kw) -> np.ndarray:
    """Expected counts of the same capture without hidden objects (DENALI's NOOBJECT)."""
    return expected_histogram(scene.without_objects(), sensor, **kw)


def sample(scene: Scene, sensor: SensorConfig, rng=0, repeats: int = 1, **kw) -> np.ndarray:
    """Noisy captures: Poisson counts of the expectation, 24-bit clipped.

    Parameters
    ----------
    rng : int or jax random key
        Explicit randomness.
    repeats : int
        Independent captures.
    **kw
        As :func:`expected_histogram`.

    Returns
    -------
    ndarray of int64, shape (repeats, rows, cols, n_bins) (or (repeats, zones, n_bins))
    """
    backend = kw.pop("backend", "fast")
    if backend == "mitsuba":
        _check(scene, sensor, backend)
        from nlosplan.simulators.mitsuba.simulator import TwinSimulator

        return TwinSimulator(scene, sensor, fidelity=kw.get("fidelity", "default"), zones=kw.get("zones")).sample(
            rng, repeats)
    return _simulator(scene, sensor, backend, **kw).sample(rng, repeats)


def explain(scene: Scene, sensor: SensorConfig, *, fidelity="default", zones=None, prune: bool = True) -> SimPlan:
    """The plan of terms: what is computed for this scene, what is left out, and why.

    Returns
    -------
    SimPlan
        ``str(plan.explain())`` is a table; ``plan.to_dict()`` is JSON-friendly.
    """
    _check(scene, sensor, "fast")
    return build_plan(scene, sensor, fidelity, zones=zones, prune=prune)


@dataclass(frozen=True)
class SimulationResult:
    """Everything one simulated capture produces.

    Attributes
    ----------
    expected : ndarray, shape (rows, cols, bins)
        Expected counts with the object.
    background : ndarray
        Expected counts without it (NOOBJECT).
    signal : ndarray
        ``expected - background``: the object's three-bounce return
        (plus any non-linear pile-up/clip interaction).
    parts : dict of ndarray
        Linear parts of ``expected`` before pile-up and clipping:
        ``direct``, ``object``, ``background`` (ambient + dark), ``crosstalk``.
    counts, background_counts : ndarray of int64, shape (repeats, ...) or None
        Noisy captures with and without the object.
    plan : SimPlan
    seconds : float
        Wall time of the simulation (plans, compilation and runs).
    meta : dict
        The scene's labels.
    """

    expected: np.ndarray
    background: np.ndarray
    signal: np.ndarray
    parts: dict
    counts: np.ndarray | None
    background_counts: np.ndarray | None
    plan: SimPlan
    seconds: float
    meta: dict = field(default_factory=dict)


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
    if backend == "mitsuba":
        _check(scene, sensor, backend)
        from nlosplan.simulators.mitsuba.backend import simulate as twin_simulate

        return twin_simulate(scene, sensor, rng=rng, repeats=repeats, fidelity=fidelity, zones=zones)
    t0 = time.perf_counter()
    if repeats and rng is None:
        raise UserError("give rng (a seed) to draw noisy captures")
    kw = dict(fidelity=fidelity, zones=zones, dtype=dtype, prune=prune)
    sim = _simulator(scene, sensor, backend, **kw)
    out = sim.expected(parts=True)
    return assemble_result(sim, out, FastSimulator(scene.without_objects(), sensor, **kw), rng, repeats,
                           plan=sim.plan, t0=t0, meta=dict(scene.meta))


def assemble_result(sim, parts: dict, bg_sim, rng, repeats: int, *, plan, t0: float, meta: dict) -> SimulationResult:
    """A :class:`SimulationResult` from a backend's simulator with and without the objects.

    Parameters
    ----------
    sim, bg_sim
        Simulators of the scene and of the scene without its objects (``expected()``, ``sample(key, n)``).
    parts : dict
        ``sim.expected(parts=True)`` (its ``counts`` is the expected capture).
    rng : int or jax random key
        Seed of the noisy captures (used when ``repeats > 0``).
    repeats : int
    plan, t0, meta
        The plan (None for backends without one), the start time and the scene labels.
    """
    background = bg_sim.expected()
    counts = bg_counts = None
    if repeats:
        import jax

        key = jax.random.key(int(rng)) if isinstance(rng, (int, np.integer)) else rng
        k1, k2 = jax.random.split(key)
        counts, bg_counts = sim.sample(k1, repeats), bg_sim.sample(k2, repeats)
    parts = dict(parts)
    expected = parts.pop("counts")
    return SimulationResult(expected=expected, background=background, signal=expected - background, parts=parts,
                            counts=counts, background_counts=bg_counts, plan=plan,
                            seconds=time.perf_counter() - t0, meta=meta)
