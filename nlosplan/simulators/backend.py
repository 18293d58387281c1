"""The backend protocol: what every simulator backend offers the backend-independent API.

A backend (``fast``: :class:`~nlosplan.simulators.fast.backend.FastBackend`;
``mitsuba``: :class:`~nlosplan.simulators.mitsuba.backend.TwinBackend`)
turns one :class:`~nlosplan.simulators.scene.Scene`, or a batch of them, and one
:class:`~nlosplan.sensor_models.config.SensorConfig` into expected counts,
noisy captures, a whole :class:`~nlosplan.simulators.result.SimulationResult`,
a :class:`~nlosplan.simulators.result.BatchResult`, or expected counts with their
derivatives (:class:`~nlosplan.simulators.result.CountsJacobian`).
:data:`nlosplan.simulators.api.BACKENDS` is the table of backends by name;
the API validates its inputs, then calls the backend the user asked for.
Adding a backend means writing a class with these methods and adding it
to that table (a backend that cannot differentiate says so in one line from
``counts_and_jacobian``).

Nuisance parameters are parameters of this seam, never edits of a backend's
internals: a caller names them (:data:`NUISANCE_PARAMETERS`) and gives their
log-changes (``theta``); the backend scales its own terms.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from nlosplan.simulators.result import BatchResult, CountsJacobian, SimulationResult

__all__ = ["Backend", "NUISANCE_PARAMETERS"]

#: Nuisance parameters of :meth:`Backend.counts_and_jacobian`, each in relative (log) units: the sensor's
#: ``photon_scale``, the floor's ``ambient`` and ``dark`` rates (``ambient_rate_hz``, ``dark_rate_hz``), and the first
#: hidden object's ``albedo``.
NUISANCE_PARAMETERS = ("photon_scale", "ambient", "dark", "albedo")


class Backend(Protocol):
    """A simulator backend (see the module notes).

    Every method takes the same keywords: ``fidelity`` (a level name, knobs or
    the backend's fidelity type), ``zones`` (``None`` or (row, col) pairs),
    ``dtype`` and ``prune`` (a backend they do not apply to ignores them).
    """

    name: str

    def expected(self, scene, sensor, *, fidelity="default", zones=None, dtype="float32",
                 prune: bool = True) -> np.ndarray:
        """Expected counts, shape (rows, cols, n_bins) or (len(zones), n_bins)."""

    def sample(self, scene, sensor, rng, repeats: int, *, fidelity="default", zones=None, dtype="float32",
               prune: bool = True) -> np.ndarray:
        """``repeats`` noisy captures, int64, shape (repeats, ...) of :meth:`expected`'s shape."""

    def simulate(self, scene, sensor, *, rng=None, repeats: int = 0, fidelity="default", zones=None,
                 dtype="float32", prune: bool = True) -> SimulationResult:
        """Expected capture, NOOBJECT background, signal, parts and optional noisy captures."""

    def expected_batch(self, scenes, sensor, *, fidelity="default", zones=None, dtype="float32", prune: bool = True,
                       parts: bool = False, chunk: int | None = None, progress=None) -> BatchResult:
        """Expected counts of every scene of a list, (N, ...) of :meth:`expected`'s shape, and optional parts.

        ``chunk`` bounds the scenes of one batched call (memory); ``progress(done, total)`` is called in scenes.
        """

    def counts_and_jacobian(self, scenes, sensor, *, fidelity="default", names=("photon_scale",), axes,
                            zones=None, theta=None, chunk: int = 25, progress=None) -> CountsJacobian:
        """Expected counts (float64) and their derivatives in the objects' displacement along ``axes`` and ``names``."""
