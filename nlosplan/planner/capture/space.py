"""The planner's model of the rig at every candidate: expected counts and their derivatives.

For each candidate gantry position the nominal simulator gives the
expected counts split into parts (first bounce ``direct``, hidden
``object``, ``floor``: dark and ambient) and the derivative of the
counts with respect to a world (x, y) shift of the object
(:func:`~nlosplan.simulators.counts_and_jacobian`, central differences of
the fast simulator in float64). The calibration parameters are

``theta = (dx, dy, log g, log a)``: a registration offset of the gantry in
the world (m), the photon scale factor ``g`` and the object albedo factor
``a``; the counts model is

``lam(theta) = floor + g (direct + a (object + J_xy (dx, dy)))``,

exact in ``g`` and ``a`` (lights off, no pile-up) and first order in the
offset.
"""

from __future__ import annotations

import hashlib
import time
from dataclasses import dataclass, field

import numpy as np

from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig

__all__ = ["CALIBRATION_PARAMETERS", "CandidateSpace", "build_space", "denali_scene_fn"]

CALIBRATION_PARAMETERS = ("dx_m", "dy_m", "log_photon_scale", "log_albedo")


def denali_scene_fn(obj: str = "A", size: str = "8in", lights: str = "off", **scene_kw):
    """``scene_fn(x_mm, y_mm)`` for the DENALI rig (:func:`nlosplan.simulators.presets.denali.scene_at`).

    ``scene_kw``: further :func:`~nlosplan.simulators.denali_scene` keywords (a calibrated sensor's scene model,
    :func:`~nlosplan.simulators.presets.scene_model.scene_options`).
    """
    from nlosplan.simulators import scene_at

    return lambda x_mm, y_mm: scene_at(obj, size, x_mm, y_mm, lights, **scene_kw)


def _labels(scenes) -> np.ndarray:
    return np.array([s.meta.get("object_xy", [np.nan, np.nan])[:2] for s in scenes], dtype=np.float64)


@dataclass(eq=False)
class CandidateSpace:
    """Candidates and the nominal simulator's counts model at each.

    Attributes
    ----------
    points_mm : ndarray, shape (C, 2)
        Gantry positions, mm.
    labels_xy : ndarray, shape (C, 2)
        Localization labels (world x, y), m.
    direct, object, floor : ndarray, shape (C, K)
        Parts of the expected counts, ``K = zones * bins``.
    jac_xy : ndarray, shape (C, K, 2)
        ``d counts / d (x, y)`` of a world shift of the object, counts per metre.
    shape : tuple of int
        ``(rows, cols, bins)`` of one histogram.
    repeats : int
        Captures per position (their mean is one observation).
    excluded : list of dict
        Positions removed by the keep-out rules, with reasons.
    meta : dict
        What built it (object, size, sensor, fidelity, seconds).
    """

    points_mm: np.ndarray
    labels_xy: np.ndarray
    direct: np.ndarray
    object: np.ndarray
    floor: np.ndarray
    jac_xy: np.ndarray
    shape: tuple
    repeats: int = 3
    excluded: list = field(default_factory=list)
    meta: dict = field(default_factory=dict)

    @property
    def size(self) -> int:
        """Number of candidates ``C``."""
        return len(self.points_mm)

    def fingerprint(self) -> str:
        """Hash of the candidate positions (a checkpoint is resumed only on the same candidates)."""
        return hashlib.sha256(np.round(self.points_mm, 3).tobytes()).hexdigest()[:16]

    def counts(self, theta=None, index=None) -> np.ndarray:
        """Expected counts of one capture, shape (C or len(index), K), under calibration ``theta`` (4,)."""
        th = np.zeros(4) if theta is None else np.asarray(theta, dtype=np.float64)
        idx = slice(None) if index is None else np.asarray(index, dtype=int)
        g, a = np.exp(th[2]), np.exp(th[3])
        obj = self.object[idx] + self.jac_xy[idx] @ th[:2]
        return np.maximum(self.floor[idx] + g * (self.direct[idx] + a * obj), 0.0)

    def jacobian(self, theta=None, index=None) -> np.ndarray:
        """``d counts / d theta``, shape (C or len(index), K, 4)."""
        th = np.zeros(4) if theta is None else np.asarray(theta, dtype=np.float64)
        idx = slice(None) if index is None else np.asarray(index, dtype=int)
        g, a = np.exp(th[2]), np.exp(th[3])
        obj = self.object[idx] + self.jac_xy[idx] @ th[:2]
        d_shift = g * a * self.jac_xy[idx]
        d_g = g * (self.direct[idx] + a * obj)
        d_a = g * a * obj
        return np.concatenate([d_shift, d_g[..., None], d_a[..., None]], axis=-1)

    def fisher(self, theta=None, index=None) -> np.ndarray:
        """Fisher information about ``theta`` of one observation (``repeats`` captures) per candidate, (C, 4, 4)."""
        from nlosplan.tasks.fisher import poisson_fisher

        return poisson_fisher(self.counts(theta, index), self.jacobian(theta, index), self.repeats)


def build_space(points_mm, sensor: SensorConfig, *, scene_fn=None, fidelity="draft", repeats: int = 3,
                excluded=(), chunk: int = 25) -> CandidateSpace:
    """Simulate the nominal counts model at every candidate.

    Parameters
    ----------
    points_mm : array_like, shape (C, 2)
        Screened candidate positions (see :func:`~nlosplan.planner.capture.keepout.screen_candidates`).
    sensor : SensorConfig
    scene_fn : callable, optional
        ``scene_fn(x_mm, y_mm) -> Scene`` (default: DENALI, letter A 8 in, lights off).
    fidelity : str
        Simulator level.
    repeats : int
        Captures per position.
    excluded : list of dict
        Keep-out records to carry along.
    chunk : int
        Scenes per compiled call.

    Returns
    -------
    CandidateSpace
    """
    from nlosplan.simulators import counts_and_jacobian, expected_batch

    t0 = time.perf_counter()
    pts = np.asarray(points_mm, dtype=np.float64).reshape(-1, 2)
    if not len(pts):
        raise UserError("no candidate positions left (all excluded?)")
    if int(repeats) < 1:
        raise UserError(f"repeats={repeats} must be >= 1")
    scene_fn = scene_fn or denali_scene_fn()
    scenes = [scene_fn(float(x), float(y)) for x, y in pts]
    if any(s.lights_on for s in scenes):
        raise UserError("the capture planner's counts model assumes lights off (ambient is not calibrated)")
    if sensor.pileup:
        raise UserError("the capture planner's counts model assumes no pile-up (a linear counts model)")
    batch = expected_batch(scenes, sensor, fidelity=fidelity, dtype="float64", chunk=chunk, parts=True)
    c = len(pts)
    flat = {k: np.asarray(v, dtype=np.float64).reshape(c, -1) for k, v in batch.parts.items()}
    _, jac, _, _ = counts_and_jacobian(scenes, sensor, fidelity=fidelity, nuisance=(), chunk=chunk)
    hist_shape = tuple(np.asarray(batch.expected).shape[1:])
    return CandidateSpace(
        points_mm=pts, labels_xy=_labels(scenes), direct=flat["direct"] + flat.get("crosstalk", 0.0),
        object=flat["object"], floor=flat["floor"], jac_xy=jac.reshape(c, -1, 2), shape=hist_shape,
        repeats=int(repeats), excluded=list(excluded),
        meta={"sensor": sensor.name, "fidelity": fidelity if isinstance(fidelity, str) else "custom",
              "scene": scenes[0].name, "seconds": time.perf_counter() - t0})
