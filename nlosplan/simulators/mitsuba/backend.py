"""The twin behind :mod:`nlosplan.simulators.api` (``backend="mitsuba"``)."""

from __future__ import annotations

import time
import warnings

import numpy as np

from nlosplan.errors import UserError
from nlosplan.simulators.mitsuba.simulator import TwinSimulator
from nlosplan.simulators.result import BatchResult, CountsJacobian, SimulationResult, assemble_result
from nlosplan.simulators.scene import NLOSWarning

__all__ = ["TwinBackend"]


def _warn_planes(scene) -> None:
    if scene.planes:
        names = ", ".join(p.name for p in scene.planes)
        warnings.warn(f"the mitsuba twin measures the relay wall only (as DENALI's twin): first-bounce returns "
                      f"of {names} are not in its histograms", NLOSWarning, stacklevel=4)


class TwinBackend:
    """:class:`~nlosplan.simulators.backend.Backend` of :class:`TwinSimulator` (seed 0 unless given).

    ``dtype`` and ``prune`` do not apply (results are float64, nothing is
    pruned); ``seed``, ``variant`` and ``illumination`` are the twin's own
    keywords (see :class:`TwinSimulator`).
    """

    name = "mitsuba"

    def expected(self, scene, sensor, *, fidelity="default", zones=None, dtype=None, prune=None, seed: int = 0,
                 variant: str = "auto", illumination: str = "flash") -> np.ndarray:
        """Expected counts of one capture rendered by the twin, (rows, cols, n_bins) or (len(zones), n_bins), float64."""
        _warn_planes(scene)
        return TwinSimulator(scene, sensor, fidelity=fidelity, zones=zones, seed=seed, variant=variant,
                             illumination=illumination).expected()

    def sample(self, scene, sensor, rng, repeats: int, *, fidelity="default", zones=None, dtype=None,
               prune=None) -> np.ndarray:
        """Poisson captures of the twin's expected counts, (repeats, ...), int64."""
        return TwinSimulator(scene, sensor, fidelity=fidelity, zones=zones).sample(rng, repeats)

    def simulate(self, scene, sensor, *, rng=None, repeats: int = 0, fidelity="default", zones=None, dtype=None,
                 prune=None, seed: int = 0, variant: str = "auto", illumination: str = "flash") -> SimulationResult:
        """Expected capture, NOOBJECT background, signal, parts and optional noisy captures, by the twin.

        The background is the same render without the hidden objects'
        three-bounce term (the twin's direct wall return does not depend on
        them); fixtures (the mount) stay in it, so the signal is exactly the
        objects' three-bounce counts through the pipeline.

        Returns
        -------
        SimulationResult
            ``plan`` is None (the twin has no plan of left-out terms); ``meta``
            gains ``twin``: fidelity, variant, seed, render seconds.
        """
        t0 = time.perf_counter()
        if repeats and rng is None:
            raise UserError("give rng (a seed) to draw noisy captures")
        _warn_planes(scene)
        sim = TwinSimulator(scene, sensor, fidelity=fidelity, zones=zones, seed=seed, variant=variant,
                            illumination=illumination)
        out = sim.expected(parts=True)
        return assemble_result(sim, out, sim.without_objects(), rng, repeats, plan=None, t0=t0,
                               meta={**scene.meta, "twin": sim.describe()})

    def expected_batch(self, scenes, sensor, *, fidelity="default", zones=None, dtype=None, prune=None,
                       parts: bool = False, chunk: int | None = None, progress=None) -> BatchResult:
        """Each scene rendered in turn (``chunk`` does not apply); the planes' warning is returned once, not warned."""
        scenes = list(scenes)
        outs, said = [], []
        for i, scene in enumerate(scenes):
            with warnings.catch_warnings(record=True) as caught:
                warnings.simplefilter("always", NLOSWarning)
                _warn_planes(scene)
            said += [str(w.message) for w in caught if str(w.message) not in said]
            sim = TwinSimulator(scene, sensor, fidelity=fidelity, zones=zones)
            outs.append(sim.expected(parts=parts))
            if progress is not None:
                progress(i + 1, len(scenes))
        fid = sim.fidelity
        if not parts:
            return BatchResult(expected=np.stack(outs), parts=None, fidelity=fid, warnings=tuple(said))
        stacked = {k: np.stack([o[k] for o in outs]) for k in outs[0]}
        return BatchResult(expected=stacked.pop("counts"), parts=stacked, fidelity=fid, warnings=tuple(said))

    def counts_and_jacobian(self, scenes, sensor, **kw) -> CountsJacobian:
        """Not offered: the twin is not differentiated (the bounds' Jacobians come from the fast backend)."""
        raise UserError("the mitsuba twin is not differentiated: use backend='fast' for expected counts with "
                        "their derivatives")

