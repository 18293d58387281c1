"""The twin behind :mod:`nlosplan.simulators.api` (``backend="mitsuba"``)."""

from __future__ import annotations

import time
import warnings

import numpy as np

from nlosplan.errors import UserError
from nlosplan.simulators.mitsuba.simulator import TwinSimulator
from nlosplan.simulators.scene import NLOSWarning


def _warn_planes(scene) -> None:
    if scene.planes:
        names = ", ".join(p.name for p in scene.planes)
        warnings.warn(f"the mitsuba twin measures the relay wall only (as DENALI's twin): first-bounce returns "
                      f"of {names} are not in its histograms", NLOSWarning, stacklevel=4)


def expected(scene, sensor, *, fidelity="default", zones=None, seed: int = 0, variant: str = "auto",
             illumination: str = "flash") -> np.ndarray:
    """Expected counts of one capture rendered by the twin (see :class:`TwinSimulator`).

    Returns
    -------
    ndarray, shape (rows, cols, n_bins) or (len(zones), n_bins), float64
    """
    _warn_planes(scene)
    return TwinSimulator(scene, sensor, fidelity=fidelity, zones=zones, seed=seed, variant=variant,
                         illumination=illumination).expected()


def simulate(scene, sensor, *, rng=None, repeats: int = 0, fidelity="default", zones=None, seed: int = 0,
             variant: str = "auto", illumination: str = "flash"):
    """Expected capture, NOOBJECT background, signal, parts and optional noisy captures, by the twin.

    The background is the same render without the hidden objects' three-bounce
    term (the twin's direct wall return does not depend on them); fixtures
    (the mount) stay in it, so the signal is exactly the objects'
    three-bounce counts through the pipeline.

    Returns
    -------
    SimulationResult
        ``plan`` is None (the twin has no plan of left-out terms); ``meta``
        gains ``twin``: fidelity, variant, seed, render seconds.
    """
    from nlosplan.simulators.api import assemble_result

    t0 = time.perf_counter()
    if repeats and rng is None:
        raise UserError("give rng (a seed) to draw noisy captures")
    _warn_planes(scene)
    sim = TwinSimulator(scene, sensor, fidelity=fidelity, zones=zones, seed=seed, variant=variant,
                        illumination=illumination)
    out = sim.expected(parts=True)
    bg_sim = TwinSimulator(scene.without_objects(), sensor, fidelity=fidelity, zones=zones, seed=seed,
                           variant=variant, illumination=illumination)
    tr = sim.transient()
    bg_sim._transient = {**tr, "object": tr["fixture"]}
    return assemble_result(sim, out, bg_sim, rng, repeats, plan=None, t0=t0,
                           meta={**scene.meta, "twin": sim.describe()})
