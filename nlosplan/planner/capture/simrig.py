"""A simulated rig: captures drawn from the simulator under a "true" calibration, and a gantry clock.

The truth differs from the planner's nominal model: the object sits
``(dx, dy)`` metres off its nominal world position (a gantry registration
error), the photon scale and the object albedo are scaled by ``exp`` of
their log-factors. The truth's expected counts are simulated exactly (not
through the planner's first-order model); each observation is the mean of
``repeats`` captures drawn by the sensor's noise model
(:class:`~nlosplan.sensor_models.noise.CaptureNoise`: Poisson, 24-bit clip).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from nlosplan.errors import UserError
from nlosplan.planner.capture.motion import MotionModel
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.noise import CaptureNoise

__all__ = ["SimulatedRig", "build_simulated_rig", "true_scene"]


def true_scene(scene, theta_true):
    """``scene`` with the object moved by ``(dx, dy)`` m (world) and its albedo scaled by ``exp(log_albedo)``."""
    th = np.asarray(theta_true, dtype=np.float64)
    objs = []
    for o in scene.objects:
        pose = np.array(o.to_world)
        pose[:2, 3] += th[:2]
        albedo = o.albedo * float(np.exp(th[3]))
        if albedo > 1:
            raise UserError(f"true albedo factor exp({th[3]:g}) makes the object albedo {albedo:.3g} > 1")
        objs.append(dataclasses.replace(o, to_world=pose, albedo=albedo))
    return scene.replace(objects=tuple(objs))


@dataclass(eq=False)
class SimulatedRig:
    """Simulator-backed captures at the candidates and at test positions.

    Attributes
    ----------
    truth : ndarray, shape (C, K)
        True expected counts of one capture at every candidate.
    test_truth : ndarray, shape (T, K)
        The same at the test positions.
    test_labels : ndarray, shape (T, 2)
        Localization labels of the test positions, m.
    theta_true : ndarray, shape (4,)
    repeats : int
    motion : MotionModel
    noise : CaptureNoise
        How a capture is drawn from its expected counts (default: Poisson without the clip).
    """

    truth: np.ndarray
    test_truth: np.ndarray
    test_labels: np.ndarray
    theta_true: np.ndarray
    repeats: int
    motion: MotionModel
    noise: CaptureNoise = CaptureNoise()

    def observe(self, index, rng) -> np.ndarray:
        """Mean of ``repeats`` captures at candidate(s) ``index``, shape (len(index), K) (:attr:`noise`)."""
        lam = self.truth[np.atleast_1d(np.asarray(index, dtype=int))]
        return self.noise.mean_of_repeats(rng, lam, self.repeats)

    def test_set(self, seed: int = 12345) -> np.ndarray:
        """Fixed noisy test observations, shape (T, K) (the same for every strategy and run)."""
        return self.noise.mean_of_repeats(np.random.default_rng(seed), self.test_truth, self.repeats)


def build_simulated_rig(space, sensor: SensorConfig, theta_true, test_points_mm, *, scene_fn=None,
                        fidelity="draft", motion: MotionModel | None = None, chunk: int = 25) -> SimulatedRig:
    """Simulate the truth at the candidates of ``space`` and at test positions.

    Parameters
    ----------
    space : CandidateSpace
    sensor : SensorConfig
        Nominal sensor; its ``photon_scale`` is multiplied by ``exp(theta_true[2])``.
    theta_true : array_like, shape (4,)
        ``(dx_m, dy_m, log_photon_scale, log_albedo)``.
    test_points_mm : array_like, shape (T, 2)
    scene_fn : callable, optional
        As :func:`~nlosplan.planner.capture.space.build_space`.
    fidelity : str
    motion : MotionModel, optional
    chunk : int

    Returns
    -------
    SimulatedRig
    """
    from nlosplan.planner.capture.space import denali_scene_fn
    from nlosplan.simulators import expected_batch

    th = np.asarray(theta_true, dtype=np.float64).reshape(4)
    scene_fn = scene_fn or denali_scene_fn()
    tests = np.asarray(test_points_mm, dtype=np.float64).reshape(-1, 2)
    pts = np.vstack([space.points_mm, tests])
    nominal = [scene_fn(float(x), float(y)) for x, y in pts]
    scenes = [true_scene(s, th) for s in nominal]
    true_sensor = sensor.replace(photon_scale=sensor.photon_scale * float(np.exp(th[2])))
    lam = expected_batch(scenes, true_sensor, fidelity=fidelity, dtype="float64", chunk=chunk).expected
    lam = np.asarray(lam, dtype=np.float64).reshape(len(pts), -1)
    c = space.size
    labels = np.array([s.meta.get("object_xy", [np.nan, np.nan])[:2] for s in nominal[c:]], dtype=np.float64)
    return SimulatedRig(truth=lam[:c], test_truth=lam[c:], test_labels=labels.reshape(-1, 2), theta_true=th,
                        repeats=space.repeats, motion=motion or MotionModel(), noise=CaptureNoise.of(true_sensor))
