"""A flat Lambertian wall in front of a flash sensor (first bounce only).

Notes
-----
For a zone sub-ray along unit direction ``omega`` with solid angle ``dOmega``
hitting the wall at range ``r`` with incidence cosine ``cos_a``, the flash
irradiates the spot with ``I(omega) cos_a / r^2`` and the Lambertian wall
sends back radiance ``albedo / pi`` times that. The zone collects

    w = I(omega) * s(omega) * dOmega * (albedo / pi) * cos_a / r^2

(aperture area and detector efficiency are folded into the sensor's
``photon_scale``), arriving at the round-trip time ``t = 2 r / c``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosplan.constants import C_M_PER_PS
from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.pipeline import expected_histogram, sample_histogram
from nlosplan.simulators.fast.geometry import direct_returns
from nlosplan.simulators.scene import LidarPose, Rect


@dataclass(frozen=True)
class WallScene:
    """A plane facing the sensor.

    Parameters
    ----------
    distance_m : float
        Distance along the optical axis to the wall, metres (> 0).
    yaw_deg, pitch_deg : float
        Tilt of the wall about the sensor's y and x axes, degrees
        (|angle| < 89); positive yaw puts the right (+x) side farther away,
        positive pitch the top (+y) side.
    albedo : float
        Lambertian albedo in [0, 1].
    lights_on : bool
        Ambient light present.
    """

    distance_m: float = 0.49
    yaw_deg: float = 0.0
    pitch_deg: float = 0.0
    albedo: float = 0.8
    lights_on: bool = False

    def __post_init__(self) -> None:
        if not (math.isfinite(self.distance_m) and self.distance_m > 0):
            raise UserError(f"wall distance {self.distance_m} m must be a finite number > 0")
        for name in ("yaw_deg", "pitch_deg"):
            v = getattr(self, name)
            if not (math.isfinite(v) and abs(v) < 89):
                raise UserError(f"wall {name}={v} is out of range; allowed: -89 < angle < 89 degrees")
        if not (math.isfinite(self.albedo) and 0 <= self.albedo <= 1):
            raise UserError(f"wall albedo={self.albedo} is out of range; allowed: 0 to 1")

    def normal(self) -> np.ndarray:
        """Unit normal of the wall pointing back at the sensor, shape (3,)."""
        y, p = math.radians(self.yaw_deg), math.radians(self.pitch_deg)
        n = np.array([math.sin(y) * math.cos(p), math.sin(p), -math.cos(y) * math.cos(p)])
        return n / np.linalg.norm(n)


def wall_arrivals(scene: WallScene, sensor: SensorConfig, n_sub: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Arrival times and weights of the first-bounce return per zone.

    Parameters
    ----------
    scene : WallScene
    sensor : SensorConfig
    n_sub : int
        Sub-rays per zone axis (fidelity knob; error falls as ``n_sub**-2``).

    Returns
    -------
    times_ps : ndarray, shape (rows, cols, n_sub**2)
        Round-trip arrival times, picoseconds.
    weights : ndarray, shape (rows, cols, n_sub**2)
        Transport weights (1/m^2 per unit flash power); 0 where a sub-ray
        misses the wall.
    """
    if n_sub < 1:
        raise ValueError("n_sub must be >= 1")
    lidar = LidarPose(position=(0.0, 0.0, 0.0), right=(1.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), forward=(0.0, 0.0, 1.0))
    n = scene.normal()
    # the plane through (0, 0, d) facing the sensor; "infinite" (1000 km), in-plane axes with u x v = n
    helper = np.array([0.0, 1.0, 0.0]) if abs(n[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
    u = np.cross(helper, n)
    wall = Rect(center=(0.0, 0.0, scene.distance_m), u_axis=u, v_axis=np.cross(n, u), half_u=1e6, half_v=1e6,
                albedo=scene.albedo, name="wall")
    path, w, _ = direct_returns(lidar, (wall,), sensor, n_sub)
    shape = (sensor.zones_rows, sensor.zones_cols, n_sub * n_sub)
    return (path / C_M_PER_PS).reshape(shape), w.reshape(shape)


def simulate_wall(scene: WallScene, sensor: SensorConfig, *, n_sub: int = 4, rng: int | None = None, repeats: int = 1):
    """Expected (``rng is None``) or sampled histograms of a wall scene.

    Returns
    -------
    ndarray, shape (rows, cols, n_bins) float64 when ``rng is None``, else
    int64 of shape (repeats, rows, cols, n_bins).
    """
    t, w = wall_arrivals(scene, sensor, n_sub)
    if rng is None:
        return np.asarray(expected_histogram(sensor, t, w, lights_on=scene.lights_on))
    return np.asarray(sample_histogram(rng, sensor, t, w, lights_on=scene.lights_on, repeats=repeats))
