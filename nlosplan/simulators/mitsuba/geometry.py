"""NumPy geometry of the twin: detection points on the wall, flash texture, time axis.

No Mitsuba here. Conventions as in :mod:`nlosplan.sensor_models.zones`
(sensor frame x right, y up, z forward; tangent plane ``u = x/z, v = y/z``;
zone row 0 on top).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosplan.constants import FWHM_PER_SIGMA
from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.transient import TimeGrid
from nlosplan.sensor_models.zones import flash_intensity, solid_angle_rect, zone_edges_tan
from nlosplan.simulators.scene import Scene

#: A Gaussian flash texture reaches this many sigmas per axis (as the fast backend's flash cells).
FLASH_SIGMAS = 3.5
#: Largest half-angle of the flash texture, degrees.
MAX_HALF_ANGLE_DEG = 80.0


@dataclass(frozen=True)
class Detection:
    """Zone sub-pixels traced to the relay wall: the film of the twin's meter.

    Attributes
    ----------
    points : ndarray, shape (H * W, 3)
        Where each sub-pixel's centre ray meets the wall plane (world, m);
        film pixel ``(iy, ix)`` is row ``iy * W + ix``.
    weight : ndarray, shape (H * W,)
        Zone sensitivity times the sub-pixel's exact solid angle (sr); 0 for
        rays that miss the wall rectangle or are not asked for.
    zone : ndarray of int, shape (H * W,)
        Flat zone index ``row * cols + col`` of each sub-pixel.
    width, height : int
        Film size ``W = cols * n_sub``, ``H = rows * n_sub``.
    """

    points: np.ndarray
    weight: np.ndarray
    zone: np.ndarray
    width: int
    height: int

    def zone_matrix(self, zones: list[int]) -> np.ndarray:
        """Weights that sum film pixels into the listed zones, shape (len(zones), H * W)."""
        return np.stack([np.where(self.zone == z, self.weight, 0.0) for z in zones])


def detection(scene: Scene, sensor: SensorConfig, n_sub: int, zones: list[int] | None = None) -> Detection:
    """Tile every zone with ``n_sub x n_sub`` sub-pixels and trace their centres to the wall.

    Parameters
    ----------
    scene : Scene
    sensor : SensorConfig
    n_sub : int
        Sub-pixels per zone axis (>= 1).
    zones : list of int, optional
        Flat zone indices to keep (the others get weight 0).

    Returns
    -------
    Detection
    """
    ue, ve = zone_edges_tan(sensor)
    rows, cols = sensor.zones_rows, sensor.zones_cols
    f = np.linspace(0.0, 1.0, n_sub + 1)
    su = (ue[:-1, None] + (ue[1:] - ue[:-1])[:, None] * f[None]).reshape(cols, n_sub + 1)
    sv = (ve[:-1, None] + (ve[1:] - ve[:-1])[:, None] * f[None]).reshape(rows, n_sub + 1)
    u_lo, u_hi = su[:, :-1].ravel(), su[:, 1:].ravel()  # (W,), left to right
    v_hi, v_lo = sv[:, :-1].ravel(), sv[:, 1:].ravel()  # (H,), top to bottom
    U_lo, V_lo = np.meshgrid(u_lo, v_lo)
    U_hi, V_hi = np.meshgrid(u_hi, v_hi)
    omega = solid_angle_rect(U_lo, U_hi, V_lo, V_hi)
    uc, vc = 0.5 * (U_lo + U_hi), 0.5 * (V_lo + V_hi)
    d = np.stack([uc, vc, np.ones_like(uc)], axis=-1)
    d /= np.linalg.norm(d, axis=-1, keepdims=True)
    sens = d[..., 2] ** sensor.sensitivity_cos_power
    world = scene.lidar.directions_to_world(d.reshape(-1, 3))
    wall = scene.wall
    denom = world @ wall.normal
    t = (wall.center - scene.lidar.position) @ wall.normal / np.where(np.abs(denom) > 1e-12, denom, np.nan)
    ok = np.isfinite(t) & (t > 0)
    t = np.where(ok, t, 1.0)
    points = scene.lidar.position + t[:, None] * world
    ok &= wall.contains(points)
    iy, ix = np.divmod(np.arange(points.shape[0]), cols * n_sub)
    zone = (iy // n_sub) * cols + ix // n_sub
    if zones is not None:
        ok &= np.isin(zone, zones)
    weight = np.where(ok, (sens * omega).ravel(), 0.0)
    if not np.any(weight > 0):
        raise UserError("no zone sub-pixel of the asked zones sees the relay wall; the twin measures the wall only")
    return Detection(points, weight, zone, cols * n_sub, rows * n_sub)


@dataclass(frozen=True)
class FlashTexture:
    """Irradiance texture of a projector that emits the sensor's flash profile.

    Mitsuba's projector with irradiance ``E(u, v)`` on its image plane at
    ``z = 1`` radiates intensity ``pi E rho^3`` (``rho^2 = 1 + u^2 + v^2``),
    so ``E = I_flash / (pi rho^3)`` reproduces
    :func:`~nlosplan.sensor_models.zones.flash_intensity` (unit power).

    Attributes
    ----------
    image : ndarray, shape (H, W), float32
        Row 0 on top (largest ``v``), column 0 on the left (smallest ``u``).
    fov_x_deg : float
        Full horizontal field of view of the texture, degrees.
    """

    image: np.ndarray
    fov_x_deg: float


def flash_texture(sensor: SensorConfig, resolution: int) -> FlashTexture:
    """Sample the flash profile on a tangent-plane grid of ``resolution`` columns."""
    if sensor.flash_profile == "uniform":
        tu = math.tan(math.radians(sensor.fov_x_deg) / 2)
        tv = math.tan(math.radians(sensor.fov_y_deg) / 2)
    else:
        lim = math.radians(MAX_HALF_ANGLE_DEG)
        sx = math.radians(sensor.flash_fwhm_x_deg) / FWHM_PER_SIGMA
        sy = math.radians(sensor.flash_fwhm_y_deg) / FWHM_PER_SIGMA
        tu, tv = math.tan(min(lim, FLASH_SIGMAS * sx)), math.tan(min(lim, FLASH_SIGMAS * sy))
    w = int(resolution)
    h = max(2, int(math.ceil(w * tv / tu)))
    tv = tu * h / w
    uc = -tu + (np.arange(w) + 0.5) * (2 * tu / w)
    vc = tv - (np.arange(h) + 0.5) * (2 * tv / h)
    uu, vv = np.meshgrid(uc, vc)
    d = np.stack([uu, vv, np.ones_like(uu)], axis=-1)
    rho = np.linalg.norm(d, axis=-1)
    image = flash_intensity(sensor, d / rho[..., None]) / (math.pi * rho**3)
    return FlashTexture(image.astype(np.float32), math.degrees(2 * math.atan(tu)))


def time_grid(sensor: SensorConfig, oversample: int) -> TimeGrid:
    """The node grid of the twin's transient film: every arrival that can reach the window."""
    return TimeGrid.for_sensor(sensor, 0.0, 1e12, oversample=int(oversample))


def film_time_axis(sensor: SensorConfig, grid: TimeGrid) -> tuple[float, float, int]:
    """``(start_opl_m, bin_width_opl_m, temporal_bins)`` of the film boxes whose centres are the grid nodes."""
    from nlosplan.constants import C_M_PER_PS

    delta = sensor.bin_width_ps / grid.oversample
    start = sensor.start_offset_ps + grid.first_bin * grid.oversample * delta
    return start * C_M_PER_PS, delta * C_M_PER_PS, grid.n_nodes
