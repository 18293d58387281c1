"""What the backends return, the same for every backend.

:class:`SimulationResult`: one simulated capture (assembled by :func:`assemble_result`); :class:`BatchResult`: the
expected counts of a batch of scenes; :class:`CountsJacobian`: expected counts and their derivatives.

Words: the *background* is the same capture without the hidden objects (DENALI's NOOBJECT); the *floor* is the
light that does not come from the flash (dark + ambient, :mod:`~nlosplan.sensor_models.noise`), a part of every
capture, background included.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np

__all__ = ["BatchResult", "CountsJacobian", "SimulationResult", "assemble_result"]


@dataclass(frozen=True)
class SimulationResult:
    """Everything one simulated capture produces.

    Attributes
    ----------
    expected : ndarray, shape (rows, cols, bins)
        Expected counts with the object.
    background : ndarray
        Expected counts of the same capture without the hidden objects (DENALI's NOOBJECT).
    signal : ndarray
        ``expected - background``: the object's three-bounce return
        (plus any non-linear pile-up/clip interaction).
    parts : dict of ndarray
        Linear parts of ``expected`` before pile-up and clipping:
        ``direct``, ``object``, ``floor`` (dark + ambient), ``crosstalk``.
    counts, background_counts : ndarray of int64, shape (repeats, ...) or None
        Noisy captures with and without the object.
    plan : object or None
        The backend's plan of computed and left-out terms (the fast backend's
        :class:`~nlosplan.simulators.fast.plan.SimPlan`: ``explain()``, ``to_dict()``), None for a backend without one.
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
    plan: Any
    seconds: float
    meta: dict = field(default_factory=dict)


@dataclass(frozen=True, eq=False)
class BatchResult:
    """Expected counts of a batch of scenes under one sensor (:func:`~nlosplan.simulators.api.expected_batch`).

    Attributes
    ----------
    expected : ndarray, shape (N, rows, cols, bins), or (N, len(zones), bins) for a subset of zones
        Expected counts of each scene (after pile-up and the 24-bit clip when enabled).
    parts : dict of ndarray or None
        With ``parts=True``: the linear parts of ``expected`` before pile-up and clipping, each shaped as it:
        ``direct``, ``object``, ``floor`` (dark + ambient), ``crosstalk``.
    fidelity : object
        The backend's resolved fidelity (``to_dict()`` gives its knobs).
    warnings : tuple of str
        What the backend says about the batch (terms it cannot model, ...): returned, not warned.
    plan : object or None
        The backend's plan (see :class:`SimulationResult`).
    """

    expected: np.ndarray
    parts: dict | None
    fidelity: Any
    warnings: tuple = ()
    plan: Any = None


class CountsJacobian(NamedTuple):
    """Expected counts and their derivatives (:func:`~nlosplan.simulators.api.counts_and_jacobian`).

    Attributes
    ----------
    lam : ndarray, shape (N, Z, B)
        Expected counts (float64).
    jac : ndarray, shape (N, Z, B, P)
        ``d lam / d theta``: counts per metre for the two displacements, counts per unit log-change for the
        nuisance parameters.
    names : tuple of str
        The P parameters, e.g. ``("x", "y", "log_photon_scale")``.
    fidelity : object
        The backend's resolved fidelity.
    """

    lam: np.ndarray
    jac: np.ndarray
    names: tuple
    fidelity: Any


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
