"""What one simulated capture produces (:class:`SimulationResult`), assembled the same way for every backend."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from nlosplan.simulators.fast.plan import SimPlan

__all__ = ["SimulationResult", "assemble_result"]


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
