"""Static geometry of the fast simulator (NumPy, built once per plan).

The LiDAR's view is tiled in its tangent plane (``u = x/z``, ``v = y/z`` in
the sensor frame, see :mod:`nlosplan.sensor_models.zones`) by rectangles:
zone sub-pixels for detection, a wider grid for the flash. Each rectangle
is a cell whose centre ray is traced to the nearest lit plane; cells that
land on the relay wall become wall quadrature cells with their corners on
the wall (for the near-field form factor), area, range and incidence cosine.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from nlosplan.constants import FWHM_PER_SIGMA
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.zones import flash_intensity, solid_angle_rect, zone_edges_tan
from nlosplan.simulators.scene import LidarPose, Rect

#: The Gaussian flash is followed out to this many sigmas per axis (power beyond: < 5e-4 per side).
FLASH_SIGMAS = 3.5
#: Widest angle (degrees off axis, per axis) any cell grid reaches.
MAX_HALF_ANGLE_DEG = 80.0


@dataclass(frozen=True)
class TangentCells:
    """Rectangles of the sensor's tangent plane.

    Attributes
    ----------
    u_lo, u_hi, v_lo, v_hi : ndarray, shape (N,)
        Bounds in ``u = tan(horizontal angle)`` and ``v = tan(vertical angle)``.
    zone : ndarray of int, shape (N,)
        Flat zone index ``row * cols + col``, or -1 outside the field of view.
    """

    u_lo: np.ndarray
    u_hi: np.ndarray
    v_lo: np.ndarray
    v_hi: np.ndarray
    zone: np.ndarray

    @property
    def center_uv(self) -> np.ndarray:
        """Centres, shape (N, 2)."""
        return np.stack([0.5 * (self.u_lo + self.u_hi), 0.5 * (self.v_lo + self.v_hi)], axis=-1)

    @property
    def solid_angle(self) -> np.ndarray:
        """Exact solid angle of each cell, sr, shape (N,)."""
        return solid_angle_rect(self.u_lo, self.u_hi, self.v_lo, self.v_hi)

    def corner_uv(self) -> np.ndarray:
        """Corners, shape (N, 4, 2), counter-clockwise in (u, v)."""
        return np.stack(
            [
                np.stack([self.u_lo, self.v_lo], -1),
                np.stack([self.u_hi, self.v_lo], -1),
                np.stack([self.u_hi, self.v_hi], -1),
                np.stack([self.u_lo, self.v_hi], -1),
            ],
            axis=1,
        )


def _outer_edges(inner: float, outer: float, n: int, pitch: float) -> np.ndarray:
    """``n`` cells from tangent ``inner`` to ``outer`` (> inner); shape (n + 1,).

    Widths grow geometrically in angle from the field-of-view pitch, so the
    cells next to the field of view (where retroreflected lobes spill into
    the zones) are as fine as the zone cells and the far tails are coarse.
    """
    a0, a1 = math.atan(inner), math.atan(outer)
    span = a1 - a0
    w0 = a0 - math.atan(inner - pitch)
    if n * w0 >= span:
        a = np.linspace(a0, a1, n + 1)
    else:
        lo, hi = 1.0, 2.0
        while w0 * (hi**n - 1) / (hi - 1) < span:
            hi *= 2
        for _ in range(100):  # bisection for the growth factor
            g = 0.5 * (lo + hi)
            lo, hi = (g, hi) if w0 * (g**n - 1) / (g - 1) < span else (lo, g)
        widths = w0 * hi ** np.arange(n)
        a = a0 + np.concatenate([[0.0], np.cumsum(widths)]) * span / widths.sum()
    e = np.tan(a)
    e[0] = inner
    return e


def _axis_edges(t_fov: float, n_inner: int, t_max: float, n_outer: int) -> np.ndarray:
    """Increasing edges: ``n_outer`` cells left of the FoV, ``n_inner`` inside, ``n_outer`` right."""
    inner = np.linspace(-t_fov, t_fov, n_inner + 1)
    if n_outer <= 0 or t_max <= t_fov * (1 + 1e-9):
        return inner
    right = _outer_edges(t_fov, t_max, n_outer, inner[1] - inner[0])
    return np.concatenate([-right[::-1][:-1], inner, right[1:]])


def flash_extent_tan(sensor: SensorConfig) -> tuple[float, float]:
    """Tangent half-extent ``(u, v)`` of the flash (its FoV for a uniform flash)."""
    lim = math.radians(MAX_HALF_ANGLE_DEG)
    if sensor.flash_profile == "uniform":
        return math.tan(math.radians(sensor.fov_x_deg) / 2), math.tan(math.radians(sensor.fov_y_deg) / 2)
    sx = math.radians(sensor.flash_fwhm_x_deg) / FWHM_PER_SIGMA
    sy = math.radians(sensor.flash_fwhm_y_deg) / FWHM_PER_SIGMA
    return math.tan(min(FLASH_SIGMAS * sx, lim)), math.tan(min(FLASH_SIGMAS * sy, lim))


def tangent_cells(sensor: SensorConfig, per_zone: int, outer: int = 0, extent: tuple[float, float] | None = None) -> TangentCells:
    """Zone-aligned cells over the field of view, optionally extended outside it.

    Parameters
    ----------
    sensor : SensorConfig
    per_zone : int
        Cells per zone per axis inside the field of view (>= 1).
    outer : int
        Cells per side per axis outside the field of view, out to ``extent``.
    extent : (float, float), optional
        Tangent half-extent to reach (default: the field of view only).

    Returns
    -------
    TangentCells
        Row-major over (v from top to bottom, u from left to right).
    """
    if per_zone < 1:
        raise ValueError("per_zone must be >= 1")
    ue, ve = zone_edges_tan(sensor)  # ve decreasing (row 0 on top)
    tu, tv = ue[-1], ve[0]
    ext = (tu, tv) if extent is None else (max(extent[0], tu), max(extent[1], tv))
    u_edges = _axis_edges(tu, sensor.zones_cols * per_zone, ext[0], outer)
    v_edges = _axis_edges(tv, sensor.zones_rows * per_zone, ext[1], outer)[::-1]  # decreasing
    uu_lo, vv_hi = np.meshgrid(u_edges[:-1], v_edges[:-1], indexing="xy")
    uu_hi, vv_lo = np.meshgrid(u_edges[1:], v_edges[1:], indexing="xy")
    uc = 0.5 * (uu_lo + uu_hi)
    vc = 0.5 * (vv_lo + vv_hi)
    col = np.searchsorted(ue, uc, side="right") - 1
    row = np.searchsorted(-ve, -vc, side="right") - 1
    inside = (col >= 0) & (col < sensor.zones_cols) & (row >= 0) & (row < sensor.zones_rows)
    inside &= (np.abs(uc) < tu) & (np.abs(vc) < tv)
    zone = np.where(inside, row * sensor.zones_cols + col, -1)
    return TangentCells(
        u_lo=uu_lo.ravel(), u_hi=uu_hi.ravel(), v_lo=vv_lo.ravel(), v_hi=vv_hi.ravel(), zone=zone.ravel()
    )


def uv_to_dirs(uv: np.ndarray) -> np.ndarray:
    """Sensor-frame unit directions (..., 3) of tangent coordinates (..., 2)."""
    u, v = uv[..., 0], uv[..., 1]
    n = np.sqrt(1.0 + u * u + v * v)
    return np.stack([u / n, v / n, 1.0 / n], axis=-1)


@dataclass(frozen=True)
class Hits:
    """Nearest lit-plane hits of rays from the LiDAR.

    Attributes
    ----------
    plane : ndarray of int, shape (N,)
        Index into ``(wall, *planes)``; -1 where the ray hits nothing.
    r : ndarray, shape (N,)
        Range to the hit, metres (1 where no hit).
    points : ndarray, shape (N, 3)
    cos : ndarray, shape (N,)
        Cosine between the plane normal and the direction back to the LiDAR.
    """

    plane: np.ndarray
    r: np.ndarray
    points: np.ndarray
    cos: np.ndarray


def trace(origin: np.ndarray, dirs: np.ndarray, rects: tuple[Rect, ...]) -> Hits:
    """Nearest hit of each ray with the lit side of any rectangle.

    Parameters
    ----------
    origin : ndarray, shape (3,)
    dirs : ndarray, shape (N, 3)
        Unit world directions.
    rects : tuple of Rect
    """
    n_rays = dirs.shape[0]
    best = np.full(n_rays, np.inf)
    plane = np.full(n_rays, -1)
    cos = np.zeros(n_rays)
    for i, rect in enumerate(rects):
        denom = dirs @ rect.normal
        front = denom < -1e-12
        safe = np.where(front, denom, -1.0)
        t = ((rect.center - origin) @ rect.normal) / safe
        p = origin + t[:, None] * dirs
        ok = front & (t > 0) & rect.contains(p) & (t < best)
        best = np.where(ok, t, best)
        plane = np.where(ok, i, plane)
        cos = np.where(ok, -safe, cos)
    hit = plane >= 0
    r = np.where(hit, best, 1.0)
    return Hits(plane=plane, r=r, points=origin + r[:, None] * dirs, cos=cos)


@dataclass(frozen=True)
class WallCells:
    """Quadrature cells on the relay wall.

    Attributes
    ----------
    centers : ndarray, shape (N, 3)
        Hit point of each cell's centre ray, metres.
    corners : ndarray, shape (N, 4, 3)
        Corner rays' hits on the wall plane (valid where ``has_polygon``).
    has_polygon : ndarray of bool, shape (N,)
        All four corner rays meet the wall plane in front of the LiDAR.
    area : ndarray, shape (N,)
        Cell area on the wall, m^2 (polygon area, else ``r^2 dOmega / cos``).
    r : ndarray, shape (N,)
        Range from the LiDAR to the centre, metres.
    cos : ndarray, shape (N,)
        Incidence cosine at the wall.
    weight : ndarray, shape (N,)
        ``I(omega) dOmega`` (flash cells, unit flash power) or
        ``s(omega) dOmega`` (detection cells), sr-weighted.
    zone : ndarray of int, shape (N,)
        Flat zone index, -1 outside the field of view.
    uv : ndarray, shape (N, 2)
        Tangent coordinates of the centre.
    """

    centers: np.ndarray
    corners: np.ndarray
    has_polygon: np.ndarray
    area: np.ndarray
    r: np.ndarray
    cos: np.ndarray
    weight: np.ndarray
    zone: np.ndarray
    uv: np.ndarray

    def __len__(self) -> int:
        return int(self.centers.shape[0])

    def select(self, mask: np.ndarray) -> "WallCells":
        """The cells where ``mask`` is true."""
        return WallCells(**{k: getattr(self, k)[mask] for k in self.__dataclass_fields__})


def _polygon_area(corners: np.ndarray) -> np.ndarray:
    """Area of planar quadrilaterals (N, 4, 3) (shoelace in 3-D)."""
    a = np.cross(corners[:, 2] - corners[:, 0], corners[:, 3] - corners[:, 1])
    return 0.5 * np.linalg.norm(a, axis=-1)


def wall_cells(
    lidar: LidarPose, wall: Rect, planes: tuple[Rect, ...], sensor: SensorConfig, cells: TangentCells, kind: str
) -> WallCells:
    """Cells of ``cells`` whose centre ray reaches the wall before any other plane.

    Parameters
    ----------
    kind : {"flash", "zone"}
        Weight by the flash intensity ``I`` (unit power) or by the zone
        sensitivity ``cos(theta)**p`` (cells outside the field of view get 0).
    """
    uv = cells.center_uv
    d_sensor = uv_to_dirs(uv)
    dirs = lidar.directions_to_world(d_sensor)
    hits = trace(lidar.position, dirs, (wall, *planes))
    on_wall = hits.plane == 0
    omega = cells.solid_angle
    if kind == "flash":
        weight = flash_intensity(sensor, d_sensor) * omega
    elif kind == "zone":
        weight = np.where(cells.zone >= 0, d_sensor[:, 2] ** sensor.sensitivity_cos_power * omega, 0.0)
    else:  # pragma: no cover - internal
        raise ValueError(kind)
    # corners on the wall plane
    c_dirs = lidar.directions_to_world(uv_to_dirs(cells.corner_uv()))  # (N, 4, 3)
    denom = c_dirs @ wall.normal
    t = ((wall.center - lidar.position) @ wall.normal) / np.where(denom < -1e-12, denom, -1.0)
    has_poly = np.all((denom < -1e-12) & (t > 0), axis=1)
    corners = lidar.position + np.where(has_poly[:, None], t, 1.0)[..., None] * c_dirs
    area = np.where(
        has_poly, _polygon_area(corners), hits.r**2 * omega / np.maximum(hits.cos, 1e-12)
    )
    keep = on_wall & (weight > 0)
    out = WallCells(
        centers=hits.points, corners=corners, has_polygon=has_poly, area=area, r=hits.r, cos=hits.cos,
        weight=weight, zone=cells.zone, uv=uv,
    )
    return out.select(keep)


def direct_returns(
    lidar: LidarPose, rects: tuple[Rect, ...], sensor: SensorConfig, per_zone: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """First-bounce returns of every zone sub-ray off the nearest lit plane.

    Returns
    -------
    path_m : ndarray, shape (Z, S)
        Round-trip optical path, metres (``S = per_zone**2``).
    weight : ndarray, shape (Z, S)
        ``I(omega) s(omega) dOmega (albedo / pi) cos / r^2`` (0 for no hit).
    plane : ndarray of int, shape (Z, S)
        Index into ``rects`` of the plane hit, -1 for none.

    Notes
    -----
    The flash irradiates the spot with ``I cos / r^2``; the Lambertian plane
    returns radiance ``albedo / pi`` times that, which the zone collects over
    the sub-ray's solid angle with its sensitivity.
    """
    cells = tangent_cells(sensor, per_zone)
    order = np.argsort(cells.zone, kind="stable")  # group by zone, keep row-major order inside
    uv = cells.center_uv[order]
    omega = cells.solid_angle[order]
    d_sensor = uv_to_dirs(uv)
    hits = trace(lidar.position, lidar.directions_to_world(d_sensor), rects)
    albedo = np.array([r.albedo for r in rects] + [0.0])[hits.plane]
    sens = d_sensor[:, 2] ** sensor.sensitivity_cos_power
    w = flash_intensity(sensor, d_sensor) * sens * omega * (albedo / math.pi) * hits.cos / hits.r**2
    w = np.where(hits.plane >= 0, w, 0.0)
    z, s = sensor.n_zones, per_zone * per_zone
    return (2.0 * hits.r).reshape(z, s), w.reshape(z, s), hits.plane.reshape(z, s)
