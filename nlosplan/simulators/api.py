"""Simulation API, independent of the backend: the one seam every room above goes through.

``expected_histogram`` / ``sample`` / ``background_histogram`` /
``explain`` / ``simulate`` take a :class:`~nlosplan.simulators.scene.Scene`
and a :class:`~nlosplan.sensor_models.config.SensorConfig`. The background
follows DENALI's NOOBJECT protocol: the same capture without the hidden
object; the signal is the capture minus the background.

Batches: :func:`expected_batch` (a list of scenes, one compiled program for
the fast backend; the design planner, the dataset build, the bounds, the
calibration, the capture planner and the rig's emulator use it) and
:func:`counts_and_jacobian` (expected counts with their derivatives in the
objects' displacement and in nuisance parameters named by the caller:
:data:`~nlosplan.simulators.backend.NUISANCE_PARAMETERS`).
:func:`direct_arrivals`: a scene's first-bounce arrivals per zone.

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

from nlosplan.constants import C_M_PER_PS
from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.simulators.backend import NUISANCE_PARAMETERS, Backend
from nlosplan.simulators.fast.backend import FastBackend
from nlosplan.simulators.fast.fidelity import resolve_fidelity
from nlosplan.simulators.fast.geometry import direct_returns
from nlosplan.simulators.fast.plan import SimPlan, build_plan
from nlosplan.simulators.mitsuba.backend import TwinBackend
from nlosplan.simulators.result import BatchResult, CountsJacobian, SimulationResult
from nlosplan.simulators.scene import Scene

__all__ = ["BACKENDS", "background_histogram", "check_backend", "counts_and_jacobian", "direct_arrivals",
           "expected_batch", "expected_histogram", "explain", "sample", "simulate"]

#: The backends by name, the one table of them ("mitsuba": the Mitsuba 3 twin; Mitsuba itself is imported on its
#: first render). The commands' ``--backend`` choices and the design TOML's ``[scenes] backend`` come from it.
BACKENDS: dict[str, Backend] = {"fast": FastBackend(), "mitsuba": TwinBackend()}


def check_backend(backend: str) -> str:
    """``backend`` if it names one of :data:`BACKENDS`, else a one-line :class:`UserError` listing them."""
    if backend not in BACKENDS:
        raise UserError(f"unknown backend {backend!r}; available: {', '.join(BACKENDS)}")
    return backend


def _check_sensor(sensor) -> None:
    if not isinstance(sensor, SensorConfig):
        raise UserError(f"sensor must be a SensorConfig (e.g. preset('tmf8828-3x3-short')), not {type(sensor).__name__}")


def _backend(scene: Scene, sensor: SensorConfig, backend: str) -> Backend:
    """The backend asked for, after checking the scene and sensor."""
    if not isinstance(scene, Scene):
        raise UserError(f"scene must be a Scene (e.g. denali_scene(...)), not {type(scene).__name__}")
    _check_sensor(sensor)
    return BACKENDS[check_backend(backend)]


def _scene_list(scenes) -> list[Scene]:
    """A non-empty list of scenes (one scene: a list of one)."""
    scenes = [scenes] if isinstance(scenes, Scene) else list(scenes)
    if not scenes:
        raise UserError("give at least one scene")
    bad = next((s for s in scenes if not isinstance(s, Scene)), None)
    if bad is not None:
        raise UserError(f"scenes must be Scenes (e.g. denali_scene(...)), not {type(bad).__name__}")
    return scenes


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


def plan_batch(scenes, sensor: SensorConfig, *, fidelity="default", min_support_sigma_ps: float = 0.0) -> SimPlan:
    """The fast simulator's plan of a batch (what :func:`expected_batch` would compile), without simulating it.

    Pass it as ``pad_to`` to a batch of a subset of these scenes (e.g. a design run's worlds, every second
    position) so that both run one compiled program.
    """
    _check_sensor(sensor)
    return build_plan(_scene_list(scenes), [sensor], fidelity, min_support_sigma_ps=min_support_sigma_ps)


def expected_batch(scenes, sensor: SensorConfig, *, backend: str = "fast", fidelity="default", zones=None,
                   dtype="float32", prune: bool = True, parts: bool = False, chunk: int | None = None,
                   progress=None, pad_to: SimPlan | None = None, min_support_sigma_ps: float = 0.0) -> BatchResult:
    """Expected counts of a batch of scenes under one sensor.

    The fast backend runs the whole list through one simulator: scenes that share the rig and the objects'
    reflectance models compile once, run in batched calls on every core, and a term that is the same in many
    scenes (a gantry's mount at one position) is computed once. The twin renders them in turn.

    Parameters
    ----------
    scenes : list of Scene
        Scenes of one rig (e.g. every DENALI object at every position).
    sensor : SensorConfig
    backend, fidelity, zones, dtype, prune
        As :func:`expected_histogram`.
    parts : bool
        Also the linear parts (``direct``, ``object``, ``floor``, ``crosstalk``) before pile-up and clipping.
    chunk : int, optional
        Scenes per compiled call (memory; the fast backend's default 25).
    progress : callable, optional
        ``progress(scenes_done, scenes)`` as the batch runs.
    pad_to : SimPlan, optional
        Fast backend: the ``plan`` of a batch run before; this batch's sizes are padded to it where smaller, so a
        sweep of batches (objects, positions) runs one compiled program (results equal within float32 rounding).
    min_support_sigma_ps : float
        Fast backend: plan the impulse response's support for at least this Gaussian sigma (ps), so batches of
        sensors with different jitter run one compiled program (equal within float32 rounding).

    Returns
    -------
    BatchResult
        ``expected`` shape (N, rows, cols, n_bins) (or (N, len(zones), n_bins)); the backend's ``warnings`` are
        returned, not warned (a caller says them once).
    """
    scenes = _scene_list(scenes)
    _check_sensor(sensor)
    if pad_to is not None and check_backend(backend) != "fast":
        raise UserError(f"pad_to is a fast-backend plan; backend {backend!r} has none")
    if min_support_sigma_ps and check_backend(backend) != "fast":
        raise UserError(f"min_support_sigma_ps sizes a fast-backend plan; backend {backend!r} has none")
    extra = {} if pad_to is None else {"pad_to": pad_to}
    if min_support_sigma_ps:
        extra["min_support_sigma_ps"] = float(min_support_sigma_ps)
    return BACKENDS[check_backend(backend)].expected_batch(scenes, sensor, fidelity=fidelity, zones=zones, dtype=dtype,
                                                           prune=prune, parts=parts, chunk=chunk, progress=progress,
                                                           **extra)


def _check_nuisance(nuisance) -> tuple[str, ...]:
    names = (nuisance,) if isinstance(nuisance, str) else tuple(nuisance or ())
    bad = [n for n in names if n not in NUISANCE_PARAMETERS]
    if bad or len(set(names)) != len(names):
        raise UserError(f"nuisance={names!r}: each at most once from {', '.join(NUISANCE_PARAMETERS)}")
    return names


def _check_axes(axes) -> np.ndarray:
    a = np.eye(3)[:2] if axes is None else np.asarray(axes, dtype=np.float64)
    if a.shape != (2, 3) or not np.all(np.isfinite(a)):
        raise UserError(f"axes must be two world directions, shape (2, 3); got {np.shape(axes)}")
    norms = np.linalg.norm(a, axis=1)
    if np.any(norms < 1e-12):
        raise UserError("axes must be non-zero directions")
    a = a / norms[:, None]
    if abs(float(a[0] @ a[1])) > 1e-6:
        raise UserError("axes must be orthogonal (the RMS error sqrt(var_0 + var_1) is a Euclidean distance)")
    return a


def counts_and_jacobian(scenes, sensor: SensorConfig, *, backend: str = "fast", fidelity="default",
                        nuisance=("photon_scale",), axes=None, zones=None, theta=None, chunk: int = 25,
                        progress=None) -> CountsJacobian:
    """Expected counts and their derivatives with respect to the objects' displacement and nuisance parameters.

    Parameters
    ----------
    scenes : Scene or list of Scene
        Scenes of one rig.
    sensor : SensorConfig
    backend : str
        From :data:`BACKENDS` (the twin is not differentiated: one line says so).
    fidelity : str, dict or Fidelity
        Simulator quadrature level.
    nuisance : sequence of str
        From :data:`~nlosplan.simulators.backend.NUISANCE_PARAMETERS`, each at most once.
    axes : array_like, shape (2, 3), optional
        Orthogonal world directions of the two displacements (default world x and y).
    zones : list of (row, col), optional
        Only these zones.
    theta : array_like, shape (2 + len(nuisance),), optional
        Evaluate at this displacement (metres) and these log-changes of the nuisances (default 0: as given).
    chunk : int
        Scenes per compiled call.
    progress : callable, optional
        ``progress(done, total)`` in scenes after each compiled call.

    Returns
    -------
    CountsJacobian
        ``lam`` (N, Z, B) float64, ``jac`` (N, Z, B, P): counts per metre for the displacements, counts per unit
        log-change for the nuisances; ``names`` such as ``("x", "y", "log_photon_scale")``; ``fidelity``.
    """
    names = _check_nuisance(nuisance)
    ax = _check_axes(axes)
    scenes = _scene_list(scenes)
    _check_sensor(sensor)
    return BACKENDS[check_backend(backend)].counts_and_jacobian(
        scenes, sensor, fidelity=fidelity, names=names, axes=ax, zones=zones, theta=theta, chunk=chunk,
        progress=progress)


def direct_arrivals(scene: Scene, sensor: SensorConfig, *,
                    fidelity="default") -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First-bounce arrivals of the scene's relay wall and planes (the table) in each zone.

    Parameters
    ----------
    scene : Scene
    sensor : SensorConfig
    fidelity : str, dict or Fidelity
        Its ``zone_sub`` sets the sub-rays per zone (``S = zone_sub**2``).

    Returns
    -------
    times_ps : ndarray, shape (Z, S)
        Arrival times, ps.
    weights : ndarray, shape (Z, S)
        Photons per iteration per unit photon scale (0 for misses).
    surface : ndarray of int, shape (Z, S)
        What each sub-ray hits first: 0 the relay wall, ``k`` the scene's plane ``k - 1``, -1 nothing.
    """
    _backend(scene, sensor, "fast")
    path, weights, surface = direct_returns(scene.lidar, (scene.wall, *scene.planes), sensor,
                                            resolve_fidelity(fidelity).zone_sub)
    return path / C_M_PER_PS, weights, surface

