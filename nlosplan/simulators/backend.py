"""The backend protocol: what every simulator backend offers the backend-independent API.

A backend (``fast``: :class:`~nlosplan.simulators.fast.backend.FastBackend`;
``mitsuba``: :class:`~nlosplan.simulators.mitsuba.backend.TwinBackend`)
turns one :class:`~nlosplan.simulators.scene.Scene` and one
:class:`~nlosplan.sensor_models.config.SensorConfig` into expected counts,
noisy captures, or a whole :class:`~nlosplan.simulators.result.SimulationResult`.
:data:`nlosplan.simulators.api.BACKENDS` is the table of backends by name;
the API validates its inputs, then calls the backend the user asked for.
Adding a backend means writing a class with these three methods and adding it
to that table.
"""

from __future__ import annotations

from typing import Protocol

import numpy as np

from nlosplan.simulators.result import SimulationResult

__all__ = ["Backend"]


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
