"""Zone geometry and the flash illumination profile.

Sensor frame: x right, y up, z forward (optical axis). Zones tile the field
of view uniformly in the image plane (tangent space ``u = x/z, v = y/z``),
like SPAD macro-pixels behind one lens. Row 0 is the top row (largest ``v``),
column 0 the left column (smallest ``u``).
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from nlosplan.sensor_models.config import SensorConfig


def zone_edges_tan(sensor: SensorConfig) -> tuple[np.ndarray, np.ndarray]:
    """Zone boundaries in tangent space.

    Returns
    -------
    u_edges : ndarray, shape (cols + 1,)
        Increasing ``tan`` of the horizontal angle at column boundaries.
    v_edges : ndarray, shape (rows + 1,)
        Decreasing ``tan`` of the vertical angle at row boundaries (row 0 on top).
    """
    tu = math.tan(math.radians(sensor.fov_x_deg) / 2)
    tv = math.tan(math.radians(sensor.fov_y_deg) / 2)
    return np.linspace(-tu, tu, sensor.zones_cols + 1), np.linspace(tv, -tv, sensor.zones_rows + 1)


def _corner(u: np.ndarray, v: np.ndarray) -> np.ndarray:
    return np.arctan(u * v / np.sqrt(1.0 + u * u + v * v))


def solid_angle_rect(u1, u2, v1, v2) -> np.ndarray:
    """Exact solid angle (sr) of the tangent-plane rectangle ``[u1,u2] x [v1,v2]``.

    Notes
    -----
    ``Omega = F(u2,v2) - F(u1,v2) - F(u2,v1) + F(u1,v1)`` with
    ``F(u, v) = atan(u v / sqrt(1 + u^2 + v^2))``; order of the bounds does
    not matter (the absolute value is returned).
    """
    u1, u2, v1, v2 = (np.asarray(a, dtype=np.float64) for a in (u1, u2, v1, v2))
    return np.abs(_corner(u2, v2) - _corner(u1, v2) - _corner(u2, v1) + _corner(u1, v1))


def zone_solid_angles(sensor: SensorConfig) -> np.ndarray:
    """Solid angle of each zone, shape ``(rows, cols)``, steradians."""
    ue, ve = zone_edges_tan(sensor)
    return solid_angle_rect(ue[None, :-1], ue[None, 1:], ve[:-1, None], ve[1:, None])


@functools.lru_cache(maxsize=64)
def _gaussian_flash_norm(fwhm_x_deg: float, fwhm_y_deg: float) -> float:
    """Integral over the forward hemisphere of the unnormalised Gaussian profile.

    Midpoint rule on a grid that spans ``min(90 deg, 12 sigma)`` per axis, so
    that narrow beams are resolved as well as wide ones.
    """
    n = 1201
    sig = np.radians([fwhm_x_deg, fwhm_y_deg]) / 2.3548200450309493
    lim = np.minimum(np.pi / 2, 12.0 * sig)
    thx = np.linspace(-lim[0], lim[0], n + 1)
    thy = np.linspace(-lim[1], lim[1], n + 1)
    tx, ty = np.meshgrid(0.5 * (thx[1:] + thx[:-1]), 0.5 * (thy[1:] + thy[:-1]), indexing="xy")
    prof = _gaussian_profile(tx, ty, fwhm_x_deg, fwhm_y_deg)
    u, v = np.tan(tx), np.tan(ty)
    du = (1 + u * u) * (thx[1] - thx[0])
    dv = (1 + v * v) * (thy[1] - thy[0])
    d_omega = du * dv / (1 + u * u + v * v) ** 1.5
    return float(np.sum(prof * d_omega))


def _gaussian_profile(theta_x, theta_y, fwhm_x_deg, fwhm_y_deg):
    sx = math.radians(fwhm_x_deg) / 2.3548200450309493
    sy = math.radians(fwhm_y_deg) / 2.3548200450309493
    return np.exp(-0.5 * ((theta_x / sx) ** 2 + (theta_y / sy) ** 2))


def flash_intensity(sensor: SensorConfig, directions: np.ndarray) -> np.ndarray:
    """Radiant intensity of the flash per steradian, normalised to unit power.

    Parameters
    ----------
    sensor : SensorConfig
    directions : ndarray, shape (..., 3)
        Unit vectors in the sensor frame.

    Returns
    -------
    ndarray, shape (...)
        Intensity (1/sr); its integral over the forward hemisphere is 1.

    Notes
    -----
    "gaussian": ``exp(-theta_x^2 / 2 s_x^2 - theta_y^2 / 2 s_y^2)`` in the
    horizontal/vertical angles ``theta = atan(u)``, FWHM per axis from the
    sensor. "uniform": constant over the zone field of view, zero outside.
    """
    d = np.asarray(directions, dtype=np.float64)
    z = d[..., 2]
    forward = z > 0
    zs = np.where(forward, z, 1.0)
    u, v = d[..., 0] / zs, d[..., 1] / zs
    if sensor.flash_profile == "uniform":
        tu = math.tan(math.radians(sensor.fov_x_deg) / 2)
        tv = math.tan(math.radians(sensor.fov_y_deg) / 2)
        inside = forward & (np.abs(u) <= tu) & (np.abs(v) <= tv)
        total = float(solid_angle_rect(-tu, tu, -tv, tv))
        return np.where(inside, 1.0 / total, 0.0)
    prof = _gaussian_profile(np.arctan(u), np.arctan(v), sensor.flash_fwhm_x_deg, sensor.flash_fwhm_y_deg)
    norm = _gaussian_flash_norm(float(sensor.flash_fwhm_x_deg), float(sensor.flash_fwhm_y_deg))
    return np.where(forward, prof / norm, 0.0)


@dataclass(frozen=True)
class ZoneRays:
    """Sub-rays that tile each zone's viewing cone.

    Attributes
    ----------
    directions : ndarray, shape (rows, cols, S, 3)
        Unit vectors (sensor frame), one per sub-pixel centre, ``S = n_sub**2``.
    solid_angle : ndarray, shape (rows, cols, S)
        Exact solid angle of each sub-pixel, sr (sums to the zone's).
    sensitivity : ndarray, shape (rows, cols, S)
        Relative zone sensitivity, ``cos(theta)**p`` (1 on axis).
    flash : ndarray, shape (rows, cols, S)
        Flash intensity along each sub-ray, 1/sr.
    """

    directions: np.ndarray
    solid_angle: np.ndarray
    sensitivity: np.ndarray
    flash: np.ndarray


def zone_rays(sensor: SensorConfig, n_sub: int = 4) -> ZoneRays:
    """Tile every zone with ``n_sub x n_sub`` sub-pixels (midpoint directions).

    Parameters
    ----------
    sensor : SensorConfig
    n_sub : int
        Sub-pixels per zone axis (>= 1); the fidelity knob of zone integration.

    Returns
    -------
    ZoneRays
    """
    if n_sub < 1:
        raise ValueError("n_sub must be >= 1")
    ue, ve = zone_edges_tan(sensor)
    rows, cols = sensor.zones_rows, sensor.zones_cols
    # sub-edges per zone: (cols, n_sub+1) and (rows, n_sub+1)
    fu = np.linspace(0.0, 1.0, n_sub + 1)
    su = ue[:-1, None] + (ue[1:] - ue[:-1])[:, None] * fu[None, :]
    sv = ve[:-1, None] + (ve[1:] - ve[:-1])[:, None] * fu[None, :]
    u1, u2 = su[:, :-1], su[:, 1:]  # (cols, n)
    v1, v2 = sv[:, :-1], sv[:, 1:]  # (rows, n)
    # broadcast to (rows, cols, n_v, n_u)
    U1 = u1[None, :, None, :]
    U2 = u2[None, :, None, :]
    V1 = v1[:, None, :, None]
    V2 = v2[:, None, :, None]
    omega = solid_angle_rect(U1, U2, V1, V2)
    uc = 0.5 * (U1 + U2) + 0.0 * V1
    vc = 0.5 * (V1 + V2) + 0.0 * U1
    norm = np.sqrt(1.0 + uc * uc + vc * vc)
    dirs = np.stack([uc / norm, vc / norm, 1.0 / norm], axis=-1)
    dirs = dirs.reshape(rows, cols, n_sub * n_sub, 3)
    omega = np.broadcast_to(omega, (rows, cols, n_sub, n_sub)).reshape(rows, cols, n_sub * n_sub)
    cos_theta = dirs[..., 2]
    sens = cos_theta**sensor.sensitivity_cos_power
    return ZoneRays(
        directions=dirs,
        solid_angle=np.ascontiguousarray(omega),
        sensitivity=sens,
        flash=flash_intensity(sensor, dirs),
    )
