"""Candidate gantry positions and the keep-out rules that remove some of them.

A position is excluded when it is outside the gantry's travel limits, or
when the hidden object would be in the LiDAR's direct view there: a ray
from the LiDAR through one of the object's vertices lies inside a zone's
viewing cone (the tangent-plane rectangles of
:func:`~nlosplan.sensor_models.zones.zone_edges_tan`) and reaches the
vertex before it reaches the relay wall, or one of the zones' sub-pixel
rays (:func:`~nlosplan.sensor_models.zones.zone_rays`) hits one of the
object's triangles before the wall (an object larger than a cone, whose
vertices all lie outside it). Such a capture would see the
object directly (first bounce), not around the corner.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.zones import zone_edges_tan, zone_rays

__all__ = ["Candidates", "direct_view_zones", "grid_points", "region_points", "screen_candidates"]


def _wall_distance(lidar, wall, dirs: np.ndarray) -> np.ndarray:
    """Distance from the LiDAR along unit rays (K, 3) to the wall rectangle, inf when a ray misses it."""
    den = dirs @ wall.normal
    num = (wall.center - lidar.position) @ wall.normal
    with np.errstate(divide="ignore", invalid="ignore"):
        t = np.where(np.abs(den) > 1e-12, num / den, np.inf)
    hit = (t > 0) & np.isfinite(t) & wall.contains(lidar.position + np.where(np.isfinite(t), t, 0.0)[:, None] * dirs)
    return np.where(hit, t, np.inf)


def _ray_triangle(origin: np.ndarray, dirs: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Nearest hit distance of rays (K, 3) from ``origin`` on triangles (T, 3, 3), shape (K,), inf for none."""
    e1, e2 = tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    pvec = np.cross(dirs[:, None, :], e2[None])                   # (K, T, 3)
    det = np.einsum("ktc,tc->kt", pvec, e1)
    ok = np.abs(det) > 1e-15
    inv = np.where(ok, 1.0 / np.where(ok, det, 1.0), 0.0)
    tvec = origin - tri[:, 0]                                     # (T, 3)
    u = np.einsum("ktc,tc->kt", pvec, tvec) * inv
    qvec = np.cross(tvec, e1)                                     # (T, 3)
    v = np.einsum("kc,tc->kt", dirs, qvec) * inv
    t = np.einsum("tc,tc->t", e2, qvec)[None, :] * inv
    hit = ok & (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 1e-9)
    return np.where(hit, t, np.inf).min(axis=1)


def direct_view_zones(scene, sensor: SensorConfig) -> list[tuple[int, int]]:
    """Zones ``(row, col)`` that see a hidden object of ``scene`` directly (empty: a true NLOS capture).

    Parameters
    ----------
    scene : Scene
    sensor : SensorConfig
        Its zone grid and field of view define the cones.

    Returns
    -------
    list of (int, int)
        Sorted zones whose cone holds an object vertex closer than the wall along that ray.
    """
    ue, ve = zone_edges_tan(sensor)
    lidar, wall = scene.lidar, scene.wall
    out: set[tuple[int, int]] = set()
    for obj in scene.objects:
        v = obj.world_vertices()
        s = lidar.points_to_sensor(v)
        front = s[:, 2] > 1e-9
        if not front.any():
            continue
        s, vw = s[front], v[front]
        u, w = s[:, 0] / s[:, 2], s[:, 1] / s[:, 2]
        inside = (u >= ue[0]) & (u <= ue[-1]) & (w <= ve[0]) & (w >= ve[-1])
        if not inside.any():
            continue
        d = vw[inside] - lidar.position
        dist = np.linalg.norm(d, axis=1)
        seen = dist < _wall_distance(lidar, wall, d / dist[:, None])
        cols = np.clip(np.searchsorted(ue, u[inside][seen], side="right") - 1, 0, len(ue) - 2)
        rows = np.clip(np.searchsorted(-ve, -w[inside][seen], side="right") - 1, 0, len(ve) - 2)
        out.update(zip(rows.tolist(), cols.tolist()))
    if scene.objects:
        rays = zone_rays(sensor, 4)
        dirs = lidar.directions_to_world(rays.directions.reshape(-1, 3))
        t_wall = _wall_distance(lidar, wall, dirs)
        for obj in scene.objects:
            t_obj = _ray_triangle(lidar.position, dirs, obj.world_vertices()[obj.mesh.faces])
            seen = (t_obj < t_wall).reshape(sensor.zones_rows, sensor.zones_cols, -1).any(axis=-1)
            out.update((int(r), int(c)) for r, c in zip(*np.nonzero(seen)))
    return sorted(out)


def grid_points(nx: int, ny: int, x_range=(0.0, 320.0), y_range=(0.0, 320.0)) -> np.ndarray:
    """A rectangular grid of gantry positions, shape (nx * ny, 2), mm, rows of constant y."""
    if nx < 1 or ny < 1:
        raise UserError(f"grid needs at least 1 x 1 points, got {nx} x {ny}")
    xs, ys = np.linspace(*x_range, nx), np.linspace(*y_range, ny)
    return np.array([(x, y) for y in ys for x in xs], dtype=np.float64)


def region_points(n: int, x_range=(0.0, 320.0), y_range=(0.0, 320.0), *, seed: int = 0) -> np.ndarray:
    """``n`` positions spread over a continuous rectangle (scrambled Halton), shape (n, 2), mm."""
    from scipy.stats import qmc

    if n < 1:
        raise UserError(f"region needs at least 1 point, got {n}")
    u = qmc.Halton(2, scramble=True, seed=seed).random(n)
    lo = np.array([x_range[0], y_range[0]], float)
    hi = np.array([x_range[1], y_range[1]], float)
    return lo + u * (hi - lo)


@dataclass(frozen=True)
class Candidates:
    """Screened candidate positions.

    Attributes
    ----------
    points_mm : ndarray, shape (C, 2)
        The positions kept, mm.
    excluded : list of dict
        ``{"x_mm", "y_mm", "reason"}`` for every position removed.
    """

    points_mm: np.ndarray
    excluded: list = field(default_factory=list)


def screen_candidates(points_mm, *, limits=((0.0, 320.0), (0.0, 320.0)), scene_fn=None,
                      sensor: SensorConfig | None = None) -> Candidates:
    """Remove positions outside the gantry limits or with the object in direct view.

    Parameters
    ----------
    points_mm : array_like, shape (K, 2)
        Proposed gantry positions, mm.
    limits : ((float, float), (float, float))
        Gantry travel per axis, mm (inclusive).
    scene_fn : callable, optional
        ``scene_fn(x_mm, y_mm) -> Scene`` with the object at that position; with
        ``sensor``, enables the direct-view test.
    sensor : SensorConfig, optional

    Returns
    -------
    Candidates
    """
    pts = np.asarray(points_mm, dtype=np.float64).reshape(-1, 2)
    if not np.all(np.isfinite(pts)):
        raise UserError("candidate positions must be finite (mm)")
    (x0, x1), (y0, y1) = limits
    keep, excluded = [], []
    for x, y in pts:
        if not (x0 - 1e-9 <= x <= x1 + 1e-9 and y0 - 1e-9 <= y <= y1 + 1e-9):
            excluded.append({"x_mm": float(x), "y_mm": float(y),
                             "reason": f"outside the gantry limits x {x0:g}-{x1:g} mm, y {y0:g}-{y1:g} mm"})
            continue
        if scene_fn is not None and sensor is not None:
            zones = direct_view_zones(scene_fn(float(x), float(y)), sensor)
            if zones:
                excluded.append({"x_mm": float(x), "y_mm": float(y),
                                 "reason": "object in the LiDAR's direct view (zones "
                                           + ", ".join(f"{r},{c}" for r, c in zones) + ")"})
                continue
        keep.append((x, y))
    return Candidates(points_mm=np.asarray(keep, dtype=np.float64).reshape(-1, 2), excluded=excluded)
