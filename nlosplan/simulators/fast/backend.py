"""The fast (JAX) backend behind :mod:`nlosplan.simulators.api` (``backend="fast"``)."""

from __future__ import annotations

import time
import warnings

import numpy as np

from nlosplan.errors import UserError
from nlosplan.simulators.fast.jacobian import counts_and_jacobian
from nlosplan.simulators.fast.simulator import FastSimulator
from nlosplan.simulators.result import BatchResult, CountsJacobian, SimulationResult, assemble_result
from nlosplan.simulators.scene import NLOSWarning

__all__ = ["FastBackend"]


def _simulator(scene, sensor, **kw) -> FastSimulator:
    """A simulator of the scene; the plan's warnings point at the caller of the API function."""
    sim = FastSimulator(scene, sensor, **kw)
    for w in sim.plan.warnings:
        warnings.warn(w, NLOSWarning, stacklevel=4)
    return sim


class FastBackend:
    """:class:`~nlosplan.simulators.backend.Backend` of :class:`~nlosplan.simulators.fast.simulator.FastSimulator`."""

    name = "fast"

    def expected(self, scene, sensor, *, fidelity="default", zones=None, dtype="float32",
                 prune: bool = True) -> np.ndarray:
        return _simulator(scene, sensor, fidelity=fidelity, zones=zones, dtype=dtype, prune=prune).expected()

    def sample(self, scene, sensor, rng, repeats: int, *, fidelity="default", zones=None, dtype="float32",
               prune: bool = True) -> np.ndarray:
        return _simulator(scene, sensor, fidelity=fidelity, zones=zones, dtype=dtype, prune=prune).sample(rng, repeats)

    def simulate(self, scene, sensor, *, rng=None, repeats: int = 0, fidelity="default", zones=None,
                 dtype="float32", prune: bool = True) -> SimulationResult:
        t0 = time.perf_counter()
        if repeats and rng is None:
            raise UserError("give rng (a seed) to draw noisy captures")
        kw = dict(fidelity=fidelity, zones=zones, dtype=dtype, prune=prune)
        sim = _simulator(scene, sensor, **kw)
        out = sim.expected(parts=True)
        return assemble_result(sim, out, FastSimulator(scene.without_objects(), sensor, **kw), rng, repeats,
                               plan=sim.plan, t0=t0, meta=dict(scene.meta))

    def expected_batch(self, scenes, sensor, *, fidelity="default", zones=None, dtype="float32", prune: bool = True,
                       parts: bool = False, chunk: int | None = None, progress=None, pad_to=None,
                       min_support_sigma_ps: float = 0.0) -> BatchResult:
        """One :class:`FastSimulator` of the whole list (its compiled batches, shared terms and threads)."""
        kw = {"pad_to": pad_to, "min_support_sigma_ps": min_support_sigma_ps}
        if chunk is not None:
            kw["chunk"] = chunk
        sim = FastSimulator(list(scenes), sensor, fidelity=fidelity, zones=zones, dtype=dtype, prune=prune, **kw)
        out = sim.expected(parts=parts, progress=progress)
        if parts:
            out = dict(out)
            return BatchResult(expected=out.pop("counts"), parts=out, fidelity=sim.plan.fidelity,
                               warnings=tuple(sim.plan.warnings), plan=sim.plan)
        return BatchResult(expected=out, parts=None, fidelity=sim.plan.fidelity, warnings=tuple(sim.plan.warnings),
                           plan=sim.plan)

    def counts_and_jacobian(self, scenes, sensor, *, fidelity="default", names=("photon_scale",), axes,
                            zones=None, theta=None, chunk: int = 25, progress=None) -> CountsJacobian:
        """Central differences of the transport in float64 (:mod:`~nlosplan.simulators.fast.jacobian`)."""
        return counts_and_jacobian(list(scenes), sensor, fidelity=fidelity, names=tuple(names), axes=axes, zones=zones,
                                   theta=theta, chunk=chunk, progress=progress)
