"""The plan of terms: what the fast simulator computes for a scene, and why.

:func:`build_plan` looks at the scene(s) and sensor(s) once, in NumPy, and
decides which terms to compute: first-bounce returns of each plane, each
object's three-bounce term (which zones, wall cells and surface samples),
ambient and dark counts, crosstalk, which parts of the impulse response. The
rest is left out with a reason (``explain``). The JAX transport then runs
only what the plan holds.

A plan serves a *batch* of scenes that share the rig (LiDAR, wall, planes,
object meshes and reflectance types) and differ in object poses, albedos
and lights; and a batch of sensors that share the static fields (zones,
bins, field of view, flash, pulse shape, pile-up, saturation) and differ in
the dynamic ones (bin width, offset, pulse and jitter widths, photon scale,
iterations, ambient, dark, crosstalk).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from nlosplan.constants import C_M_PER_PS
from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.pipeline import pulse_boxes
from nlosplan.sensor_models.transient import TimeGrid, irf_extent_ps, move_reach_ps
from nlosplan.sensor_models.zone_terms import zone_values
from nlosplan.simulators.fast.fidelity import Fidelity, resolve_fidelity
from nlosplan.simulators.fast.geometry import direct_returns, trace
from nlosplan.simulators.fast.plan_object import ObjectPlan, ObjectStatic, _zone_names, distinct_poses, plan_object
from nlosplan.simulators.meshes import _fine_cells
from nlosplan.simulators.scene import Scene

#: Sensor fields a batch may vary (traced); every other field must be equal.
DYNAMIC_SENSOR_FIELDS = (
    "bin_width_ps", "start_offset_ps", "pulse_fwhm_ps", "jitter_fwhm_ps", "photon_scale",
    "iterations", "ambient_rate_hz", "dark_rate_hz", "crosstalk",
)
#: The impulse response's support and the time grid are sized for a Gaussian sigma rounded up to this step (ps), so
#: sensors whose jitter differs a little (the design run's worlds) share one plan structure and one compiled program;
#: a wider support adds only the Gaussian's mass beyond 9 sigma (< 1e-18) and a few empty grid bins.
SUPPORT_SIGMA_STEP_PS = 50.0


def support_sigma_ps(sigma_ps: float) -> float:
    """The Gaussian sigma (ps) a plan sizes its support and grid for: ``sigma`` rounded up to :data:`SUPPORT_SIGMA_STEP_PS`
    (0 stays 0: no Gaussian)."""
    return SUPPORT_SIGMA_STEP_PS * math.ceil(float(sigma_ps) / SUPPORT_SIGMA_STEP_PS - 1e-9) if sigma_ps > 0 else 0.0


@dataclass(frozen=True)
class PlanStatic:
    """Hashable structure of a plan: the key under which JAX caches compiled code."""

    grid: TimeGrid
    n_zones: int
    direct: bool
    crosstalk: bool
    irf: str
    pulse: tuple | None
    extent: tuple[float, float]
    nominal_bin_width: float
    pileup: bool
    saturation: bool
    ambient: bool
    dark: bool
    objects: tuple[ObjectStatic, ...]
    object_rows: tuple[tuple[int, ...], ...]
    zone_terms: tuple[str, ...] = ()
    spads: int = 1
    dead_time_ps: float | None = None
    walk_ps: float = 0.0
    deposit: str = "window"


@dataclass(frozen=True)
class Term:
    """One line of :func:`explain`: a term, whether it is computed, and why."""

    computed: bool
    name: str
    reason: str


@dataclass(frozen=True, eq=False)
class SimPlan:
    """Static decisions and arrays for a batch of scenes and sensors.

    Attributes
    ----------
    static : PlanStatic
    arrays : dict
        NumPy arrays the transport needs (``direct_*`` and one dict per object).
    zones : ndarray of int
        Flat indices (``row * cols + col``) of the output zones.
    full_grid : bool
        All zones are output (results reshape to ``(rows, cols, bins)``).
    terms : tuple of Term
    warnings : tuple of str
    sensor : SensorConfig
        The first sensor (static fields).
    fidelity : Fidelity
    paths : int
        Path evaluations per scene.
    object_index : tuple of int
        Index into ``scene.objects`` of each computed object term.
    object_albedo : tuple of str
        Per computed object term, the object attribute that is its albedo
        (``"albedo"``, or ``"diffuse_albedo"`` for the diffuse base of a
        retroreflective object, which is a Lambertian term of its own).
    object_samples : tuple of list
        Per computed object term, the surface quadrature of each distinct
        mesh (points, normals, areas; object frame, one padded size).
    object_mesh_index : tuple of ndarray
        Per computed object term, which quadrature each scene uses, shape (N,).
    object_near_index : tuple of dict
        Per computed object term and leg, each scene's near-wall cell indices.
    """

    static: PlanStatic
    arrays: dict
    zones: np.ndarray
    full_grid: bool
    terms: tuple
    warnings: tuple
    sensor: SensorConfig
    fidelity: Fidelity
    paths: int
    object_index: tuple = ()
    object_albedo: tuple = ()
    object_samples: tuple = ()
    object_mesh_index: tuple = ()
    object_near_index: tuple = ()

    def explain(self) -> str:
        """Text table of computed and left-out terms with the reason for each."""
        lines = [f"plan for {self.sensor.name} ({self.sensor.zones_rows}x{self.sensor.zones_cols} zones, "
                 f"{self.sensor.n_bins} bins), fidelity {self.fidelity.to_dict()}: {self.paths:,} paths per scene"]
        width = max(len(t.name) for t in self.terms)
        for t in self.terms:
            lines.append(f"  {'computed' if t.computed else 'left out':<9} {t.name:<{width}}  {t.reason}")
        for w in self.warnings:
            lines.append(f"  warning: {w}")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """JSON-friendly summary: terms, warnings, zones, paths, fidelity."""
        return {
            "computed": [dataclasses.asdict(t) for t in self.terms if t.computed],
            "left_out": [dataclasses.asdict(t) for t in self.terms if not t.computed],
            "warnings": list(self.warnings),
            "zones": self.zones.tolist(),
            "paths_per_scene": self.paths,
            "fidelity": self.fidelity.to_dict(),
            "time_grid": dataclasses.asdict(self.static.grid),
        }


def _resolve_zones(sensor: SensorConfig, zones) -> tuple[np.ndarray, bool]:
    if zones is None:
        return np.arange(sensor.n_zones), True
    out = []
    for z in zones:
        try:
            r, c = (int(v) for v in z)
        except (TypeError, ValueError):
            raise UserError(f"zone {z!r} must be a (row, col) pair") from None
        if not (0 <= r < sensor.zones_rows and 0 <= c < sensor.zones_cols):
            raise UserError(f"zone ({r},{c}) is outside the {sensor.zones_rows}x{sensor.zones_cols} grid; allowed: "
                            f"rows 0..{sensor.zones_rows - 1}, columns 0..{sensor.zones_cols - 1}")
        out.append(r * sensor.zones_cols + c)
    if not out:
        raise UserError("no zones requested; give at least one (row, col)")
    twice = sorted({z for z in out if out.count(z) > 1})
    if twice:
        z = twice[0]
        raise UserError(f"zone ({z // sensor.zones_cols},{z % sensor.zones_cols}) is requested twice")
    return np.array(out), False


def _check_batch(scenes: list[Scene]) -> None:
    base = scenes[0]
    for s in scenes[1:]:
        same = (
            (s.lidar is base.lidar
             or (np.allclose(s.lidar.basis, base.lidar.basis) and np.allclose(s.lidar.position, base.lidar.position)))
            and _same_rect(s.wall, base.wall) and len(s.planes) == len(base.planes)
            and all(_same_rect(a, b) for a, b in zip(s.planes, base.planes))
            and len(s.objects) == len(base.objects)
            and all(a.reflectance == b.reflectance and a.lobe_fwhm_deg == b.lobe_fwhm_deg and a.fixture == b.fixture
                    and a.support == b.support
                    for a, b in zip(s.objects, base.objects))
        )
        if not same:
            raise UserError("a batch of scenes must share the rig (LiDAR, wall, planes), the number of objects, "
                            "their reflectance models, fixture flags and support flags; object meshes, poses, albedos "
                            "and lights may differ")


def _same_rect(a, b) -> bool:
    return a is b or (np.allclose(a.center, b.center) and np.allclose(a.u_axis, b.u_axis)
                      and np.allclose(a.v_axis, b.v_axis) and a.half_u == b.half_u and a.half_v == b.half_v
                      and a.albedo == b.albedo)


def _check_sensors(sensors: list[SensorConfig]) -> None:
    base = sensors[0].to_dict()
    for s in sensors[1:]:
        d = s.to_dict()
        bad = [k for k in base if k not in DYNAMIC_SENSOR_FIELDS + ("name", "notes") and d[k] != base[k]]
        if bad:
            raise UserError(f"sensors in one batch may differ only in {', '.join(DYNAMIC_SENSOR_FIELDS)}; "
                            f"these differ: {', '.join(bad)}")
    # the plan's node grid counts bins of one time base: a batch with another bin width or start lost object
    # light (16 % at a 5 % wider bin); a single sensor's time base stays differentiable
    for name in ("bin_width_ps", "start_offset_ps"):
        if len({float(getattr(s, name)) for s in sensors}) > 1:
            raise UserError(f"sensors in one batch must share their time base; {name} differs: simulate each "
                            "time base in a batch of its own")


def _outside_view(scene: Scene, sensor: SensorConfig, objs: list) -> np.ndarray:
    """Per object, True when its bounding sphere lies wholly behind the LiDAR or beyond a side of its field of
    view (so none of its points is in view), (len(objs),) bool. Conservative: False says nothing."""
    centre, radius = np.empty((len(objs), 3)), np.empty(len(objs))
    for i, obj in enumerate(objs):
        centre[i], radius[i] = obj.bounding_sphere()
    x, y, z = scene.lidar.points_to_sensor(centre).T
    tu, tv = math.tan(math.radians(sensor.fov_x_deg) / 2), math.tan(math.radians(sensor.fov_y_deg) / 2)
    # signed distances to the pyramid's side planes |x| = tu z and |y| = tv z (positive outside)
    side_u = (np.abs(x) - tu * z) / math.hypot(1.0, tu)
    side_v = (np.abs(y) - tv * z) / math.hypot(1.0, tv)
    return (z + radius < 0) | (side_u > radius) | (side_v > radius)


def _dense_world_points(objs: list) -> np.ndarray:
    """Vertices and centroids of small pieces (edges <= 1/16 of the object size) of every pose, (P, 3)."""
    out, seen, posed = [], {}, set()
    for obj in objs:
        mesh = obj.mesh
        key = (id(mesh), np.asarray(obj.to_world).tobytes())
        if key in posed:  # e.g. a mount at one gantry position under every object
            continue
        posed.add(key)
        if id(mesh) not in seen:
            diag = float(np.linalg.norm(np.ptp(mesh.vertices, axis=0)))
            cen, _, _ = _fine_cells(mesh, mesh.face_areas > 0, diag / 16, np.inf, 20_000)
            seen[id(mesh)] = np.concatenate([mesh.vertices, cen])
        r, t = obj.to_world[:3, :3], obj.to_world[:3, 3]
        out.append(seen[id(mesh)] @ r.T + t)
    return np.concatenate(out) if out else np.zeros((0, 3))


def _in_view_zones(scene: Scene, sensor: SensorConfig, objs: list) -> list[int]:
    """:func:`_direct_view_zones` of the objects' dense points, skipping the poses wholly out of view
    (:func:`_outside_view`: a batch of hidden objects costs a sphere test per pose, not thousands of points)."""
    outside = _outside_view(scene, sensor, objs)
    return _direct_view_zones(scene, sensor, _dense_world_points([o for o, out in zip(objs, outside) if not out]))


def _direct_view_zones(scene: Scene, sensor: SensorConfig, points: np.ndarray) -> list[int]:
    """Zones in whose cone some of ``points`` (world, (N, 3)) are nearer than the wall."""
    p = scene.lidar.points_to_sensor(points)
    z = p[:, 2]
    front = z > 1e-9
    zs = np.where(front, z, 1.0)
    u, v = p[:, 0] / zs, p[:, 1] / zs
    tu, tv = math.tan(math.radians(sensor.fov_x_deg) / 2), math.tan(math.radians(sensor.fov_y_deg) / 2)
    inside = front & (np.abs(u) <= tu) & (np.abs(v) <= tv)
    if not np.any(inside):
        return []
    pts = points[inside]
    rng = np.linalg.norm(pts - scene.lidar.position, axis=1)
    hits = trace(scene.lidar.position, (pts - scene.lidar.position) / rng[:, None], (scene.wall, *scene.planes))
    seen = (hits.plane < 0) | (rng < hits.r)
    if not np.any(seen):
        return []
    col = np.clip(((u[inside][seen] + tu) / (2 * tu) * sensor.zones_cols).astype(int), 0, sensor.zones_cols - 1)
    row = np.clip(((tv - v[inside][seen]) / (2 * tv) * sensor.zones_rows).astype(int), 0, sensor.zones_rows - 1)
    return sorted(set((row * sensor.zones_cols + col).tolist()))


def support_fidelity(fid: Fidelity) -> Fidelity:
    """The knobs a support part (``HiddenObject.support``) is planned with: ``support_samples`` surface samples and
    ``support_flash_sub`` lit wall cells per zone axis (its detection cells and outer lit cells are the object's)."""
    return dataclasses.replace(fid, object_samples=fid.support_samples, flash_sub=fid.support_flash_sub)


def _object_parts(objs: list, fid: Fidelity) -> tuple[list[tuple[str, str, str, Fidelity]], list[Term]]:
    """The transport terms of one object over a batch, and lines for :func:`explain`.

    Returns
    -------
    parts : list of (kind, part name, albedo attribute, fidelity)
        A retroreflective object with a diffuse base (``diffuse_albedo > 0``
        in any scene of the batch) gets a second, Lambertian term with the
        fidelity's ``diffuse_samples`` surface samples; its zero-albedo
        scenes get exactly zero from it. A support part (``obj.support``:
        DENALI's mount and plate) is sampled with the fidelity's
        ``support_samples``.
    lines : list of Term
        A fixture's (it stays in the background capture) and a left-out
        diffuse base's.
    """
    obj = objs[0]
    parts = [(obj.reflectance, "", "albedo", support_fidelity(fid) if obj.support else fid)]
    lines = []
    if obj.fixture:
        lines.append(Term(True, f"object {obj.name!r}: fixture", "moves with the gantry and stays in the background "
                          "capture (DENALI's NOOBJECT): it is in the capture and the background, not in the signal"))
    if obj.reflectance == "retroreflective":
        if any(o.diffuse_albedo > 0 for o in objs):
            parts.append(("lambertian", "diffuse base", "diffuse_albedo",
                          dataclasses.replace(fid, object_samples=fid.diffuse_samples)))
        else:
            lines.append(Term(False, f"object {obj.name!r}: diffuse base",
                              "diffuse_albedo 0: a pure retroreflector (no Lambertian term)"))
    return parts, lines


def _moves(sensor: SensorConfig) -> float:
    """Largest move (ps) of the sensor's zone clocks and time walk near its window (see ``move_reach_ps``)."""
    lo, hi = irf_extent_ps(sensor)
    t0 = sensor.start_offset_ps
    return move_reach_ps(sensor, max(abs(t0 - hi), abs(t0 + sensor.window_ps - lo)))


def _irf_term(sensor: SensorConfig, sigma_max: float, prune: bool, planned: float = 0.0) -> tuple[str, Term]:
    pulse = sensor.pulse_shape is not None
    if not prune or sigma_max > 0 or planned > 0:
        what = ("measured pulse (*) " if pulse else "") + f"Gaussian (largest sigma {sigma_max:.1f} ps"
        what += f"; planned for {planned:.1f} ps, so batches of other jitter share its program)" if planned > 0 else ")"
        return "full", Term(True, "impulse response", what + ", closed form per grid node")
    if pulse:
        return "pulse", Term(False, "impulse response: Gaussian", "jitter 0 and no Gaussian pulse width: only the "
                             "measured pulse shape is convolved (exact box overlaps, no erf)")
    return "none", Term(False, "impulse response", "jitter 0, no pulse: ideal impulse response, no convolution")


def _pileup_reason(sensor: SensorConfig) -> str:
    if not sensor.pileup:
        return "off in this sensor"
    dead = "blind for the rest of the iteration" if sensor.dead_time_ps is None else \
        f"non-paralyzable dead time {sensor.dead_time_ps:g} ps"
    return f"{sensor.spads_per_zone} detector(s) per zone, {dead}; ambient and dark counts count toward it"


def build_plan(scenes, sensors, fidelity="default", *, zones=None, prune: bool = True,
               min_support_sigma_ps: float = 0.0) -> SimPlan:
    """Plan the fast simulation of a batch of scenes and sensors.

    Parameters
    ----------
    scenes : Scene or list of Scene
        Scenes sharing the rig; object poses, albedos and lights may differ.
    sensors : SensorConfig or list of SensorConfig
        Sensors sharing the static fields (see :data:`DYNAMIC_SENSOR_FIELDS`).
    fidelity : str, dict or Fidelity
    zones : list of (row, col), optional
        Only these zones (default all).
    prune : bool
        Leave out terms, zones, cells and samples that cannot contribute.
    min_support_sigma_ps : float
        Size the impulse response's support and the time grid for at least this Gaussian sigma (ps), as for
        the sensors' own largest (both rounded up to :data:`SUPPORT_SIGMA_STEP_PS`), and with a Gaussian in the
        impulse response even where every sensor's sigma is 0: batches whose sensors differ in jitter (a design
        run's worlds, and its nominal references without jitter) then share one structure and one compiled
        program. It adds only the Gaussian's mass beyond 9 sigma and empty grid bins.

    Returns
    -------
    SimPlan
    """
    if not (math.isfinite(float(min_support_sigma_ps)) and float(min_support_sigma_ps) >= 0.0):
        raise UserError(f"min_support_sigma_ps={min_support_sigma_ps!r} must be a finite number >= 0")
    scenes = [scenes] if isinstance(scenes, Scene) else list(scenes)
    sensors = [sensors] if isinstance(sensors, SensorConfig) else list(sensors)
    if not scenes or not sensors:
        raise UserError("need at least one scene and one sensor")
    _check_batch(scenes)
    _check_sensors(sensors)
    fid = resolve_fidelity(fidelity)
    base, sensor = scenes[0], sensors[0]
    zones_out, full_grid = _resolve_zones(sensor, zones)
    terms: list[Term] = []
    if not full_grid:
        terms.append(Term(False, "zones", f"only {len(zones_out)} of {sensor.n_zones} zones requested"))
    rects = (base.wall, *base.planes)
    path, w, plane = direct_returns(base.lidar, rects, sensor, fid.zone_sub)
    path, w, plane = path[zones_out], w[zones_out], plane[zones_out]
    for i, rect in enumerate(rects):
        n_hit = int((plane == i).sum())
        reason = (f"{n_hit} of {plane.size} zone sub-rays see it first" if n_hit else
                  "no zone sub-ray reaches it before another surface (or it is outside the field of view)")
        terms.append(Term(n_hit > 0, f"first bounce: {rect.name}", reason))
    direct = bool(np.any(w > 0))

    sigmas = [s.impulse_sigma_ps for s in sensors]
    sigma_max = max(sigmas)
    # the support's sigma: sensors of nearby jitter (and batches sized for one sigma) share one plan structure
    support = support_sigma_ps(max(sigma_max, float(min_support_sigma_ps)))
    # arrival times that can reach the window through the impulse response and the time walk's largest shift
    reach = (min(s.start_offset_ps - irf_extent_ps(s, support)[1] - _moves(s) for s in sensors),
             max(s.start_offset_ps + s.window_ps - irf_extent_ps(s, support)[0] + _moves(s) for s in sensors))
    # latest possible arrival: direct paths and the farthest object path via the wall's corners
    t_hi = float(path.max()) / C_M_PER_PS if direct else 0.0
    r_wall = float(np.linalg.norm(base.wall.corners() - base.lidar.position, axis=1).max())
    corners = base.wall.corners()
    for k in range(len(base.objects)):
        for obj in distinct_poses([sc.objects[k] for sc in scenes])[0]:
            d = np.linalg.norm(corners[:, None] - obj.world_vertices()[None], axis=-1).max()
            t_hi = max(t_hi, 2 * (r_wall + float(d)) / C_M_PER_PS)
    grids = [TimeGrid.for_sensor(s, 0.0, t_hi, oversample=fid.time_oversample, sigma_ps=support) for s in sensors]
    first = min(g.first_bin for g in grids)
    last = max(g.first_bin + g.n_grid_bins for g in grids)
    grid = TimeGrid(fid.time_oversample, first, last - first, sensor.n_bins)

    obj_plans: list[ObjectPlan] = []
    obj_index: list[int] = []
    obj_albedo: list[str] = []
    warnings: list[str] = []
    cells: dict = {}  # wall cells of the plan, built once and shared by every object term
    for k, obj in enumerate(base.objects):
        objs = [sc.objects[k] for sc in scenes]
        parts, extra = _object_parts(objs, fid)
        for i, (kind, part, attr, f) in enumerate(parts):
            plan, notes = plan_object(k, objs, base, sensor, f, zones_out, grid, reach, prune, kind=kind, part=part,
                                      cells=cells)
            terms.extend(Term(*n) for n in notes)
            if i == 0:
                terms.extend(extra)
            if plan is not None:
                obj_plans.append(plan)
                obj_index.append(k)
                obj_albedo.append(attr)
        seen = _in_view_zones(base, sensor, objs)
        if seen:
            warnings.append(f"object {obj.name!r} is inside the LiDAR's direct field of view (zones "
                            f"{_zone_names(seen, sensor)}): this is "
                            "not an NLOS capture; only its three-bounce light is simulated")
    if not base.objects:
        terms.append(Term(False, "hidden object", "none in the scene (background, like DENALI's NOOBJECT capture)"))

    irf, irf_term = _irf_term(sensor, sigma_max, prune, float(min_support_sigma_ps))
    terms.append(irf_term)
    lights = any(sc.lights_on for sc in scenes)
    ambient = (lights and any(s.ambient_rate_hz > 0 for s in sensors)) or not prune
    terms.append(Term(ambient, "ambient light",
                      "lights on: ambient photons in every bin" if lights and ambient else
                      ("lights off" if not lights else "the sensor's ambient rate is 0")))
    dark = any(s.dark_rate_hz > 0 for s in sensors) or not prune
    terms.append(Term(dark, "dark counts", "dark-count rate > 0" if dark else "dark-count rate is 0"))
    crosstalk = any(s.crosstalk > 0 for s in sensors) or not prune
    terms.append(Term(crosstalk, "crosstalk", "cover-glass return at zero path" if crosstalk else "crosstalk is 0"))
    terms.append(Term(sensor.pileup, "pile-up", _pileup_reason(sensor)))
    terms.append(Term(sensor.saturation, "saturation", "24-bit clip" if sensor.saturation else "off in this sensor"))
    zv = zone_values(sensor, zones_out)
    for key, name, what, neutral in (
            ("gains", "zone gains", "per-zone gain", "all 1"),
            ("offsets_ps", "zone time offsets", "per-zone TDC delay, nodes moved", "all 0"),
            ("scales", "zone time scales", "per-zone TDC rate, nodes moved", "all 1"),
            ("overlap_m", "near-field overlap", "r^2 / (r^2 + d0^2) per zone, r = c t / 2", "all 0")):
        on = zv[key] is not None
        terms.append(Term(on, name, what if on else f"{neutral} in this sensor"))
    walk = sensor.time_walk_ps != 0
    terms.append(Term(walk, "time walk", f"{sensor.time_walk_ps:g} ps earlier per decade of a zone's light, "
                      "nodes moved per scene" if walk else "time_walk_ps is 0"))
    tail = sensor.pulse_tail_fraction > 0
    terms.append(Term(tail, "pulse tail", f"exponential, {sensor.pulse_tail_fraction:.2g} of the pulse, "
                      f"decay {sensor.pulse_tail_decay_ps:g} ps" if tail else "pulse_tail_fraction is 0"))

    p = pulse_boxes(sensor)
    pulse = None if p is None else (tuple(p[0].tolist()), float(p[1]), tuple(p[2].tolist()))
    lo, hi = irf_extent_ps(sensor, support)
    static = PlanStatic(
        grid=grid, n_zones=len(zones_out), direct=direct, crosstalk=crosstalk, irf=irf, pulse=pulse, extent=(lo, hi),
        nominal_bin_width=float(sensor.bin_width_ps), pileup=sensor.pileup, saturation=sensor.saturation,
        ambient=ambient, dark=dark, objects=tuple(o.static for o in obj_plans),
        object_rows=tuple(tuple(int(r) for r in o.zone_rows) for o in obj_plans),
        zone_terms=tuple(k for k, v in zv.items() if v is not None), spads=int(sensor.spads_per_zone),
        dead_time_ps=None if sensor.dead_time_ps is None else float(sensor.dead_time_ps),
        walk_ps=float(sensor.time_walk_ps),
    )
    s = path.shape[1]
    arrays = {
        "direct_path": path.ravel(), "direct_w": w.ravel(), "direct_row": np.repeat(np.arange(len(zones_out)), s),
        "objects": [o.arrays for o in obj_plans],
        "zone": {k: v for k, v in zv.items() if v is not None},
    }
    paths = int(np.sum(w > 0)) + sum(o.paths for o in obj_plans)
    return SimPlan(static=static, arrays=arrays, zones=zones_out, full_grid=full_grid, terms=tuple(terms),
                   warnings=tuple(warnings), sensor=sensor, fidelity=fid, paths=paths, object_index=tuple(obj_index),
                   object_albedo=tuple(obj_albedo), object_samples=tuple(o.samples for o in obj_plans),
                   object_mesh_index=tuple(o.mesh_index for o in obj_plans),
                   object_near_index=tuple(o.near_index for o in obj_plans))



#: The sizes of an object term that :func:`pad_plan` may raise (each only adds weightless nodes, cells or samples).
_GROWABLE = ("near1", "near2", "n1", "n2", "n_r")


def _sample_count(plan: SimPlan, k: int) -> int:
    return len(plan.object_samples[k][0][0]) if plan.object_samples[k] else 0


def pad_plan(plan: SimPlan, like: SimPlan | None) -> SimPlan:
    """``plan`` with its object terms' sizes raised to ``like``'s where larger, so both run one compiled program.

    Plans of one rig and sensor differ, from batch to batch (e.g. one DENALI object after another), only in a
    few sizes of their object terms: the near-wall blocks, the time ranges of the legs (``n1``, ``n2``,
    ``n_r``) and the surface samples. Each is padded with exactly nothing: near blocks with the out-of-range
    cell index, samples with zero area, time ranges with nodes beyond the arrivals (the legs' convolution
    stays linear: ``fft_len = n1 + n2``). The result equals ``plan``'s within float32 rounding.

    Parameters
    ----------
    plan : SimPlan
    like : SimPlan or None
        A plan compiled before (None, or a plan of another structure: ``plan`` unchanged).

    Returns
    -------
    SimPlan
        Same static structure as ``like`` when every size of ``plan`` is at most ``like``'s.
    """
    if like is None or len(plan.static.objects) != len(like.static.objects):
        return plan
    a, b = plan.static, like.static
    same_rest = all(getattr(a, f.name) == getattr(b, f.name) for f in dataclasses.fields(PlanStatic)
                    if f.name not in ("objects", "deposit"))
    shapes = jax_shapes(plan.arrays) == jax_shapes(like.arrays)
    if not (same_rest and shapes and all(
            (x.kind, x.lobe, x.n_rows) == (y.kind, y.lobe, y.n_rows) for x, y in zip(a.objects, b.objects))):
        return plan
    objects, samples, near_index = [], [], []
    for k, (x, y) in enumerate(zip(a.objects, b.objects)):
        grown = {f: max(getattr(x, f), getattr(y, f)) for f in _GROWABLE}
        if x.kind == "lambertian":
            grown["fft_len"] = grown["n1"] + grown["n2"]
        objects.append(dataclasses.replace(x, **grown))
        size = max(_sample_count(plan, k), _sample_count(like, k))
        samples.append([_pad_samples(s, size) for s in plan.object_samples[k]])
        near = {}
        for leg, idx in plan.object_near_index[k].items():
            n_cells = plan.arrays["objects"][k][f"c{leg}t"].shape[1]
            block = grown[f"near{leg}"]
            near[leg] = [np.concatenate([i, np.full(block - len(i), n_cells, np.int64)]) for i in idx]
        near_index.append(near)
    static = dataclasses.replace(a, objects=tuple(objects))
    return dataclasses.replace(plan, static=static, object_samples=tuple(samples), object_near_index=tuple(near_index))


def _pad_samples(s: tuple, size: int) -> tuple:
    """Surface samples ``(points, normals, areas)`` padded to ``size`` with zero-area copies of the last one."""
    pts, nrm, area = s[:3]
    pad = size - len(pts)
    if pad <= 0:
        return s
    return (np.concatenate([pts, np.repeat(pts[-1:], pad, 0)]), np.concatenate([nrm, np.repeat(nrm[-1:], pad, 0)]),
            np.concatenate([area, np.zeros(pad)])) + tuple(s[3:])


def jax_shapes(tree) -> list:
    """The shapes of a tree's array leaves, in order (the part of a compiled program's key that is not static)."""
    from nlosplan._jax import jax

    return [np.shape(x) for x in jax.tree_util.tree_leaves(tree)]
