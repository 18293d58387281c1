"""Plan of one hidden object's three-bounce term (static, NumPy).

Decides which surface samples, wall cells and zones the object's term needs
for a batch of poses, sizes its time axes, and says what it left out.
"""

from __future__ import annotations

import dataclasses
import hashlib
from collections import OrderedDict
import math
from dataclasses import dataclass

import numpy as np

from nlosplan.constants import C_M_PER_PS, FWHM_PER_SIGMA
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.simulators.fast.fidelity import Fidelity
from nlosplan.simulators.fast.transport import GRAZING_SIGMAS
from nlosplan.simulators.fast.geometry import WallCells, flash_extent_tan, tangent_cells, wall_cells
from nlosplan.simulators.meshes import surface_quadrature
from nlosplan.simulators.scene import HiddenObject, Scene
from nlosplan.sensor_models.transient import TimeGrid
from nlosplan.sensor_models.zones import zone_edges_tan

#: Node axes are rounded up to a multiple of this, so nearby scenes share compiled code.
BUCKET = 64
#: Surface points are padded (with zero area) to a multiple of this, for shared compiled code.
SAMPLE_BUCKET = 16
#: Object points closer to a wall cell than this many cell sizes use the exact polygon coupling
#: (the midpoint rule overestimates by about (size / distance)^2 / 3: 3.7 % for that cell at 3 cell
#: sizes, under 1 % beyond 6; the total, a mean over many cells, moves far less: DENALI's errors
#: against the reference are the same with 2 to 8 cell sizes, at a fifth of the cost with 3).
NEAR_CELLS = 3.0
#: A sample-to-cell pair uses the exact coupling within NEAR_CELLS cell sizes; the plan gives a scene the exact
#: block for every cell within NEAR_CELLS + NEAR_MARGIN cell sizes of one of its surface samples.
NEAR_MARGIN = 0.5
#: Lobe tails are followed this many sigmas across zone boundaries.
LOBE_SIGMAS = 6.0


def bucket(n: int) -> int:
    """``n`` rounded up to a multiple of :data:`BUCKET` (at least one bucket)."""
    return max(BUCKET, -(-int(n) // BUCKET) * BUCKET)


@dataclass(frozen=True)
class ObjectStatic:
    """Hashable shape information of an object term (the jit cache key)."""

    kind: str
    near1: int
    near2: int
    lobe: bool
    n_rows: int
    n1: int = 0
    n2: int = 0
    fft_len: int = 0
    n_r: int = 0


@dataclass(frozen=True, eq=False)
class ObjectPlan:
    """Static arrays and decisions for one hidden object.

    Attributes
    ----------
    static : ObjectStatic
    arrays : dict of ndarray
        Wall cells, lobe geometry and node offsets (see
        :mod:`nlosplan.simulators.fast.transport`).
    zone_rows : ndarray of int
        Rows of the simulator's output zones that receive this term.
    paths : int
        Path evaluations per scene.
    samples : list of (points (M, 3), normals (M, 3), areas (M,))
        Surface quadrature of each distinct mesh in the batch (object frame,
        padded to one size ``M``); they are dynamic scene parameters.
    mesh_index : ndarray of int, shape (N,)
        Which entry of ``samples`` each scene of the batch uses.
    near_index : dict of leg -> list of ndarray of int
        Per scene, the wall cells of each leg that need the exact coupling
        (padded to the static block size with an out-of-range index).
    """

    static: ObjectStatic
    arrays: dict
    zone_rows: np.ndarray
    paths: int
    samples: list
    mesh_index: np.ndarray
    near_index: dict


#: :func:`_visible_faces` of recent plans, by mesh content, poses and wall: a design run's worlds plan the same
#: objects at the same poses under other albedos and sensors (0.2 s of a 1,500-scene plan's 0.66 s).
_VISIBLE_CACHE: OrderedDict = OrderedDict()
_VISIBLE_CACHE_SIZE = 512


def _visible_faces(obj_list: list[HiddenObject], scene: Scene) -> np.ndarray:
    """Faces of ``obj_list[0].mesh`` that see some part of the wall, in front of it, in any pose of the list."""
    mesh = obj_list[0].mesh
    corners = scene.wall.corners()
    poses = np.unique(np.stack([np.asarray(o.to_world, np.float64) for o in obj_list]), axis=0)  # (P, 4, 4)
    key = (mesh.content_key, hashlib.sha1(poses.tobytes()).hexdigest(), np.asarray(corners, np.float64).tobytes())
    hit = _VISIBLE_CACHE.get(key)
    if hit is None:
        hit = _VISIBLE_CACHE[key] = _faces_seeing_the_wall(mesh, poses, scene, corners)
        hit.setflags(write=False)
        while len(_VISIBLE_CACHE) > _VISIBLE_CACHE_SIZE:
            _VISIBLE_CACHE.popitem(last=False)
    _VISIBLE_CACHE.move_to_end(key)
    return hit


def _faces_seeing_the_wall(mesh, poses: np.ndarray, scene: Scene, corners: np.ndarray) -> np.ndarray:
    """:func:`_visible_faces` for distinct poses (P, 4, 4)."""
    tri, fn, fa = mesh.triangles, mesh.face_normals, mesh.face_areas
    r, t = poses[:, :3, :3], poses[:, :3, 3]
    n_w, w0 = scene.wall.normal, scene.wall.center
    # every pose at once: a face sees the wall when some corner is in front of it, and is in front of the wall
    rt = r.transpose(0, 2, 1)
    cen = tri.mean(axis=1)[None] @ rt + t[:, None]  # (P, F, 3) face centres in the world
    nw = fn[None] @ rt  # (P, F, 3) world normals
    sees = (nw @ corners.T - np.sum(nw * cen, axis=-1, keepdims=True)).max(axis=2) > 0  # (P, F)
    height = (n_w @ r) @ tri.reshape(-1, 3).T + ((t - w0) @ n_w)[:, None]  # (P, 3F) vertex heights over the wall
    front = height.reshape(len(poses), -1, 3).max(axis=2) > 0
    return np.any(sees & front, axis=0) & (fa > 0)


def _by_mesh(obj_list: list[HiddenObject]) -> tuple[list[list[HiddenObject]], np.ndarray]:
    """Group the batch by mesh: the groups, and each scene's group index (N,)."""
    groups: list[list[HiddenObject]] = []
    where: dict[int, int] = {}
    index = np.empty(len(obj_list), np.int64)
    for i, obj in enumerate(obj_list):
        k = where.setdefault(id(obj.mesh), len(groups))
        if k == len(groups):
            groups.append([])
        groups[k].append(obj)
        index[i] = k
    return groups, index


def distinct_poses(obj_list: list[HiddenObject]) -> tuple[list[HiddenObject], np.ndarray]:
    """The batch's distinct (mesh, pose) pairs, and each scene's index among them (N,).

    A dataset's batch repeats them: an object under both lightings, the gantry's mount under every object at a
    position; the plan's geometry (bounding spheres, time bounds, heights) is computed once per distinct pair.
    """
    index: dict = {}
    first: list[HiddenObject] = []
    inverse = np.empty(len(obj_list), np.int64)
    for i, obj in enumerate(obj_list):
        key = (id(obj.mesh), np.asarray(obj.to_world, np.float64).tobytes())
        j = index.setdefault(key, len(first))
        if j == len(first):
            first.append(obj)
        inverse[i] = j
    return first, inverse


#: Bounding spheres of recent poses, by mesh content and pose (the worlds' plans pose the same objects again).
_SPHERE_CACHE: OrderedDict = OrderedDict()
_SPHERE_CACHE_SIZE = 50_000


def _bounding_spheres(obj_list: list[HiddenObject]) -> tuple[np.ndarray, np.ndarray]:
    """Centre (P, 3) and radius (P,) of every pose's vertices."""
    cs, rs = [], []
    for obj in obj_list:
        key = (obj.mesh.content_key, np.asarray(obj.to_world, np.float64).tobytes())
        hit = _SPHERE_CACHE.get(key)
        if hit is None:
            v = obj.world_vertices()
            c = 0.5 * (v.min(0) + v.max(0))
            hit = _SPHERE_CACHE[key] = (c, float(np.linalg.norm(v - c, axis=1).max()))
            if len(_SPHERE_CACHE) > _SPHERE_CACHE_SIZE:
                _SPHERE_CACHE.popitem(last=False)
        cs.append(hit[0])
        rs.append(hit[1])
    return np.array(cs), np.array(rs)


def _leg_bounds(cells: WallCells, centers: np.ndarray, radii: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per cell, the min and max of ``r + |x_cell - x|`` over all poses' spheres (metres)."""
    d = np.linalg.norm(cells.centers[:, None, :] - centers[None], axis=-1)  # (N, P)
    lo = cells.r[:, None] + np.maximum(d - radii[None], 0.0)
    hi = cells.r[:, None] + d + radii[None]
    return lo.min(axis=1), hi.max(axis=1)


def _tangent_jacobian(scene: Scene, cells: WallCells) -> np.ndarray:
    """d(u, v)/d(world position) at each cell centre, shape (N, 2, 3)."""
    lid = scene.lidar
    p = cells.centers - lid.position
    z = p @ lid.forward
    u = (p @ lid.right) / z
    v = (p @ lid.up) / z
    ju = (lid.right[None] - u[:, None] * lid.forward[None]) / z[:, None]
    jv = (lid.up[None] - v[:, None] * lid.forward[None]) / z[:, None]
    return np.stack([ju, jv], axis=1)


def _lobe_spread(scene: Scene, cells: WallCells, jac: np.ndarray, centers: np.ndarray, radii: np.ndarray, sigma: float) -> np.ndarray:
    """Largest tangent-plane spread of the retro lobe landing at each cell (N,)."""
    n_w = scene.wall.normal
    out = np.zeros(len(cells))
    for c, rad in zip(centers, radii):
        e = cells.centers - c
        dist = np.linalg.norm(e, axis=1)
        e = e / dist[:, None]
        en = np.minimum(e @ n_w, -math.sin(GRAZING_SIGMAS * sigma))  # as the transport holds it
        jp = jac - (jac @ e[:, :, None]) / en[:, None, None] * n_w[None, None, :]
        s = (dist + rad) * sigma * np.linalg.norm(jp, axis=2).max(axis=1)
        out = np.maximum(out, s)
    return out


def _pad(pts: np.ndarray, nrm: np.ndarray, area: np.ndarray, size: int) -> tuple[np.ndarray, ...]:
    """Pad surface points to ``size`` with zero-area copies (they contribute exactly nothing)."""
    pad = size - len(pts)
    if pad <= 0:
        return pts, nrm, area
    p0 = pts[:1] if len(pts) else np.zeros((1, 3))
    n0 = nrm[:1] if len(nrm) else np.array([[0.0, 0.0, 1.0]])
    return (np.concatenate([pts, np.repeat(p0, pad, 0)]), np.concatenate([nrm, np.repeat(n0, pad, 0)]),
            np.concatenate([area, np.zeros(pad)]))


#: Surface quadratures of recent plans, by mesh (the mesh itself is kept, so its id stays its own), sample count,
#: seed, visible faces and pruning: a sweep plans the same mesh (a DENALI object, the gantry's mount) batch after
#: batch, and its quadrature (0.1-0.3 s a mesh) is the same each time.
_SAMPLE_CACHE: OrderedDict = OrderedDict()
_SAMPLE_CACHE_SIZE = 256


def _samples(obj: HiddenObject, vis: np.ndarray, fid: Fidelity, prune: bool, seed: int):
    key = (id(obj.mesh), int(fid.object_samples), int(seed), np.asarray(vis, bool).tobytes(), bool(prune))
    hit = _SAMPLE_CACHE.get(key)
    if hit is not None and hit[0] is obj.mesh:
        _SAMPLE_CACHE.move_to_end(key)
        return hit[1]
    out = _new_samples(obj, vis, fid, prune, seed)
    _SAMPLE_CACHE[key] = (obj.mesh, out)
    while len(_SAMPLE_CACHE) > _SAMPLE_CACHE_SIZE:
        _SAMPLE_CACHE.popitem(last=False)
    return out


def _new_samples(obj: HiddenObject, vis: np.ndarray, fid: Fidelity, prune: bool, seed: int):
    mesh = obj.mesh
    s = surface_quadrature(mesh, fid.object_samples, seed=seed, face_mask=vis)
    pts, nrm, area = s.points, s.normals, s.areas
    n_hidden = 0
    if not prune:
        inv = (~vis) & (mesh.face_areas > 0)
        a_vis, a_inv = mesh.face_areas[vis].sum(), mesh.face_areas[inv].sum()
        n_inv = int(round(fid.object_samples * a_inv / a_vis)) if a_vis > 0 else fid.object_samples
        if n_inv > 0 and a_inv > 0:
            t = surface_quadrature(mesh, n_inv, seed=seed + 1, face_mask=inv)
            pts, nrm, area = (np.concatenate([a, b]) for a, b in ((pts, t.points), (nrm, t.normals), (area, t.areas)))
            n_hidden = n_inv
    return pts, nrm, area, n_hidden


def _near_cells(cells: WallCells, thr: np.ndarray, sphere_dist: np.ndarray, obj_list: list[HiddenObject], sets: list,
                mesh_index: np.ndarray) -> list[np.ndarray]:
    """Per scene, the wall cells that some surface sample of its object comes within ``thr`` of (plus a margin).

    The transport uses the exact polygon coupling for a sample and a cell closer than the cell's ``thr``
    (:func:`~nlosplan.simulators.fast.transport._coupling`) and the midpoint rule otherwise, so only those cells
    need the (costly) exact block; every other pair gets the midpoint value either way. Candidates are the cells
    within ``thr`` of the pose's bounding sphere (``sphere_dist`` (N, scenes): centre distance minus radius); of
    those, the cells within ``thr + NEAR_MARGIN * cell size`` of one of the posed samples are kept (the margin
    covers float32 rounding and small displacements of the pose, e.g. a Jacobian's differences). A tall part
    (DENALI's mount post) has a bounding sphere far larger than its cross-section: 19-32 cells per scene by the
    sphere, far fewer by its samples.

    Returns
    -------
    list of ndarray of int
        Per scene (the order of ``obj_list``), sorted cell indices.
    """
    cand_all = cells.has_polygon[:, None] & (sphere_dist < thr[:, None])  # (N, scenes)
    reach = thr + NEAR_MARGIN * np.sqrt(cells.area)
    out, memo = [], {}
    for j, obj in enumerate(obj_list):
        cand = np.flatnonzero(cand_all[:, j])
        if not len(cand):
            out.append(cand)
            continue
        key = (int(mesh_index[j]), np.asarray(obj.to_world, np.float64).tobytes(), cand.tobytes())
        if key not in memo:
            pts, _, area, _ = sets[int(mesh_index[j])]
            x = pts[area > 0] @ obj.to_world[:3, :3].T + obj.to_world[:3, 3]  # (M, 3) posed samples
            d2 = ((cells.centers[cand][None] - x[:, None]) ** 2).sum(-1).min(0)  # (K,)
            memo[key] = cand[d2 < reach[cand] ** 2]
        out.append(memo[key])
    return out


def plan_object(
    index: int,
    obj_list: list[HiddenObject],
    scene: Scene,
    sensor: SensorConfig,
    fid: Fidelity,
    zones_out: np.ndarray,
    grid: TimeGrid,
    reach_ps: tuple[float, float],
    prune: bool,
    kind: str | None = None,
    part: str = "",
    cells: dict | None = None,
) -> tuple[ObjectPlan | None, list]:
    """Plan one object's term for all poses in ``obj_list``.

    Returns ``(plan, notes)``; ``plan`` is None when nothing can contribute.
    ``notes`` are ``(computed, name, reason)`` lines for :func:`explain`.

    Parameters
    ----------
    index : int
        Position of the object in the scene (seeds its sampling).
    obj_list : list of HiddenObject
        The object in every scene of the batch.
    scene : Scene
        The first scene (shared rig).
    zones_out : ndarray of int
        Flat zone indices the simulator outputs.
    grid : TimeGrid
        The sensor node grid.
    reach_ps : (float, float)
        Arrival times that can reach the window through the impulse response.
    prune : bool
        Leave out what cannot contribute (False: compute everything, for tests).
    kind : {"retroreflective", "lambertian"}, optional
        The transport of this term (default: the object's reflectance); the
        diffuse base of a retroreflective object is a ``"lambertian"`` term.
    part : str
        Name of the part in :func:`explain` lines (e.g. ``"diffuse base"``).
    cells : dict, optional
        Wall cells already built for this plan, by kind and grid knobs,
        filled here when missing: the terms of one plan share them.
    """
    obj = obj_list[0]
    kind = obj.reflectance if kind is None else kind
    label = f"object {obj.name!r}" if len({id(o.mesh) for o in obj_list}) == 1 else f"objects ({obj.reflectance})"
    if part:
        label = f"{label}: {part}"
    notes: list = []
    groups, mesh_index = _by_mesh(obj_list)
    vis_list = [_visible_faces(g, scene) for g in groups]
    if not any(np.any(v) for v in vis_list):
        notes.append((False, label, "no face of the object can see the relay wall in any pose"))
        if prune:
            return None, notes
    sets = [_samples(g[0], v, fid, prune, seed=fid.seed + 7919 * index) for g, v in zip(groups, vis_list)]
    n_points = max(len(p) for p, *_ in sets)
    size = -(-max(n_points, 1) // SAMPLE_BUCKET) * SAMPLE_BUCKET
    samples = [_pad(p, n, a, size) for p, n, a, _ in sets]  # zero-area padding contributes nothing
    n_hidden = max(h for *_, h in sets)
    n_vis = int(vis_list[0].sum())
    n_faces = len(vis_list[0])
    uniq, inverse = distinct_poses(obj_list)
    centers, radii = _bounding_spheres(uniq)  # (U, 3), (U,): each distinct pose once
    retro = kind == "retroreflective"
    lobe_sigma = math.radians(obj.lobe_fwhm_deg) / FWHM_PER_SIGMA
    lobe = retro and lobe_sigma > 0

    ext = flash_extent_tan(sensor)
    cells = {} if cells is None else cells
    key = ("flash", fid.flash_sub, fid.flash_outer)
    if key not in cells:
        cells[key] = wall_cells(scene.lidar, scene.wall, scene.planes, sensor,
                                tangent_cells(sensor, fid.flash_sub, fid.flash_outer, ext), "flash")
    flash = cells[key]
    zones_set = set(int(z) for z in zones_out)
    row_of = {int(z): i for i, z in enumerate(zones_out)}
    arrays: dict = {"lobe_sigma": np.array(lobe_sigma)}

    if retro:
        jac = _tangent_jacobian(scene, flash)
        keep = np.isin(flash.zone, list(zones_set))
        if lobe:
            # cells whose lobe can reach a requested zone: within LOBE_SIGMAS spreads of one
            spread = _lobe_spread(scene, flash, jac, centers, radii, lobe_sigma) * LOBE_SIGMAS
            ue, ve = zone_edges_tan(sensor)
            rows_, cols_ = np.divmod(np.array(sorted(zones_set)), sensor.zones_cols)
            u, v = flash.uv[:, 0], flash.uv[:, 1]
            near_zone = np.zeros(len(flash), bool)
            for r_, c_ in zip(rows_, cols_):
                du = np.maximum(np.maximum(ue[c_] - u, u - ue[c_ + 1]), 0.0)
                dv = np.maximum(np.maximum(ve[r_ + 1] - v, v - ve[r_]), 0.0)
                near_zone |= np.hypot(du, dv) <= spread
            keep = near_zone
        if not prune:
            keep = np.ones(len(flash), bool)
        left = int((~keep).sum())
        if left:
            notes.append((False, f"{label}: flash cells", f"{left} of {len(flash)} wall cells left out: a retroreflector "
                          "returns light where it was lit, and they lie outside the requested zones"
                          + (" beyond the lobe's reach" if lobe else "")))
        flash, jac = flash.select(keep), jac[keep]
        t_lo, t_hi = _leg_bounds(flash, centers, radii)
        zone_lo = {z: 2 * t_lo[flash.zone == z].min() / C_M_PER_PS for z in zones_set if np.any(flash.zone == z)}
        zone_hi = {z: 2 * t_hi[flash.zone == z].max() / C_M_PER_PS for z in zones_set if np.any(flash.zone == z)}
        if lobe:  # a lobe can carry any cell's light into a neighbouring zone: use the all-cell range
            lo_all, hi_all = 2 * t_lo.min() / C_M_PER_PS, 2 * t_hi.max() / C_M_PER_PS
            zone_lo = {z: lo_all for z in zones_set}
            zone_hi = {z: hi_all for z in zones_set}
    else:
        key = ("zone", fid.zone_sub)
        if key not in cells:
            cells[key] = wall_cells(scene.lidar, scene.wall, scene.planes, sensor, tangent_cells(sensor, fid.zone_sub),
                                    "zone")
        det = cells[key]
        det = det.select(np.isin(det.zone, list(zones_set)))
        t1_lo, t1_hi = _leg_bounds(flash, centers, radii)
        t2_lo, t2_hi = _leg_bounds(det, centers, radii)
        zone_lo = {z: (t1_lo.min() + t2_lo[det.zone == z].min()) / C_M_PER_PS for z in zones_set if np.any(det.zone == z)}
        zone_hi = {z: (t1_hi.max() + t2_hi[det.zone == z].max()) / C_M_PER_PS for z in zones_set if np.any(det.zone == z)}

    no_wall = sorted(zones_set - set(zone_lo))
    late = sorted(z for z in zone_lo if zone_lo[z] > reach_ps[1] or zone_hi[z] < reach_ps[0])
    obj_zones = [z for z in zones_out if int(z) in zone_lo and (int(z) not in late or not prune)]
    if no_wall:
        notes.append((False, f"{label}: zones", f"{len(no_wall)} zone(s) see no relay wall, so no three-bounce light: "
                      + _zone_names(no_wall, sensor)))
    if late and prune:
        notes.append((False, f"{label}: zones", f"{len(late)} zone(s) left out: their earliest three-bounce arrival is "
                      f"after the window (or all before it): " + _zone_names(late, sensor)))
    if not obj_zones:
        lo = min(zone_lo.values()) if zone_lo else float("nan")
        notes.append((False, label, f"outside the time window: earliest arrival {lo / 1000:.2f} ns, window reaches "
                      f"{reach_ps[0] / 1000:.2f}..{reach_ps[1] / 1000:.2f} ns through the impulse response"))
        return None, notes
    zone_rows = np.array([row_of[int(z)] for z in obj_zones])
    local_row = {int(z): i for i, z in enumerate(obj_zones)}
    if not retro:  # detection cells of the computed zones only
        det_rows = np.array([local_row.get(int(z), -1) for z in det.zone])
        keep = det_rows >= 0
        det, det_rows, t2_lo, t2_hi = det.select(keep), det_rows[keep], t2_lo[keep], t2_hi[keep]

    # near field: per scene, the cells its object can come within NEAR_CELLS cell sizes of use the exact
    # form factor; their indices are dynamic scene parameters (padded), the block size is static
    near_index: dict[str, list[np.ndarray]] = {}
    n_near = {"1": 0, "2": 0}
    for leg in ("1",) if retro else ("1", "2"):
        cells = flash if leg == "1" else det
        thr = NEAR_CELLS * np.sqrt(cells.area)
        dist = (np.linalg.norm(cells.centers[:, None] - centers[None], axis=-1) - radii[None])[:, inverse]  # (N, scenes)
        near_index[leg] = _near_cells(cells, thr, dist, obj_list, sets, mesh_index)
        n_near[leg] = max(len(i) for i in near_index[leg])
        arrays.update({f"c{leg}t": cells.centers.T.copy(), f"k{leg}": cells.corners, f"a{leg}": cells.area,
                       f"r{leg}": cells.r, f"thr{leg}": thr})
    near = n_near["1"] + n_near["2"] > 0
    h_min = min(float(scene.wall.signed_distance(o.world_vertices()).min()) for o in uniq)
    arrays["n_w"] = scene.wall.normal
    arrays["w0"] = scene.wall.center
    arrays["wall_corners"] = scene.wall.corners()
    notes.append((near, f"{label}: near-wall quadrature",
                  (f"object {h_min * 1000:.1f} mm from the wall: up to {n_near['1'] + n_near['2']} wall cells per "
                   f"scene it can come within {NEAR_CELLS:g} cell sizes of use the exact polygon form factor" if near
                   else f"object >= {h_min * 100:.1f} cm from the wall, beyond {NEAR_CELLS:g} cell sizes of every "
                   f"cell: midpoint kernel (at most {100 / (3 * NEAR_CELLS**2):.1f} % per cell, far less in total)")))
    # near points: cell boxes in wall coordinates, the wall's axes and the LiDAR
    for leg, cells in (("1", flash),) if retro else (("1", flash), ("2", det)):
        wall_uv = np.stack([(cells.corners - scene.wall.center) @ scene.wall.u_axis,
                            (cells.corners - scene.wall.center) @ scene.wall.v_axis], axis=-1)  # (N, 4, 2)
        arrays[f"box{leg}"] = np.stack([wall_uv[..., 0].min(1), wall_uv[..., 0].max(1),
                                        wall_uv[..., 1].min(1), wall_uv[..., 1].max(1)], axis=1)
    lid = scene.lidar
    arrays.update(wall_u=scene.wall.u_axis, wall_v=scene.wall.v_axis,
                  lidar=np.stack([lid.position, lid.right, lid.up, lid.forward]))
    # radiance of the wall cell per unit flash power: (albedo / pi) I dOmega / A
    arrays["l1"] = scene.wall.albedo / math.pi * flash.weight / flash.area
    delta = sensor.bin_width_ps / grid.oversample
    t0 = sensor.start_offset_ps
    lo_t, hi_t = max(min(zone_lo[z] for z in obj_zones), reach_ps[0]), min(max(zone_hi[z] for z in obj_zones), reach_ps[1])
    m = n_points
    if retro:
        n1 = len(flash)
        # receive factor: the lobe lands around x1, seen with s(omega) cos / r^2 (albedo / pi of the wall)
        d_sensor = scene.lidar.points_to_sensor(flash.centers)
        cosz = d_sensor[:, 2] / np.linalg.norm(d_sensor, axis=1)
        sens = cosz**sensor.sensitivity_cos_power
        arrays["recv"] = scene.wall.albedo / math.pi * sens * flash.cos / flash.r**2
        # near-wall pairs land anywhere in their cell: widen the time range by a cell diagonal each way
        margin = 2 * float(np.linalg.norm(flash.corners[:, 2] - flash.corners[:, 0], axis=1).max()) / C_M_PER_PS \
            if n_near["1"] else 0.0
        k_lo = math.floor(float(grid.node_position(lo_t - margin, sensor.bin_width_ps, t0))) - 1
        k_hi = math.ceil(float(grid.node_position(hi_t + margin, sensor.bin_width_ps, t0))) + 2
        ue, ve = zone_edges_tan(sensor)
        arrays.update(u_edges=ue, nv_edges=-ve, cell_row=np.array([local_row.get(int(z), -1) for z in flash.zone]),
                      wall_rho_pi=np.array(scene.wall.albedo / math.pi),
                      sens_power=np.array(float(sensor.sensitivity_cos_power)))
        n_r = bucket(k_hi - k_lo)
        arrays["k_r0"] = np.array(k_lo)
        if lobe:
            arrays.update(uv=flash.uv, jac=jac, obj_zones=np.array(obj_zones))
        else:
            onehot = np.zeros((n1, len(obj_zones)))
            for i, z in enumerate(flash.zone):
                if int(z) in local_row:
                    onehot[i, local_row[int(z)]] = 1.0
            arrays["frac"] = onehot
        static = ObjectStatic("retroreflective", 0, 0, lobe, len(obj_zones), n_r=n_r)
        paths = m * n1
        how = (f"retroreflective ({obj.lobe_fwhm_deg:g} deg lobe), {m} surface samples on {n_vis} of {n_faces} faces"
               f" x {n1} lit wall cells = {paths:,} paths")
    else:
        t1_lo_all, t1_hi_all = t1_lo.min() / C_M_PER_PS, t1_hi.max() / C_M_PER_PS
        t2_lo_all, t2_hi_all = t2_lo.min() / C_M_PER_PS, t2_hi.max() / C_M_PER_PS
        t1_hi_all = min(t1_hi_all, reach_ps[1] - t2_lo_all)
        t2_hi_all = min(t2_hi_all, reach_ps[1] - t1_lo_all)
        j1 = math.floor((t1_lo_all - t0) / delta - 0.5) - 1
        n1 = bucket(math.ceil((t1_hi_all - t0) / delta - 0.5) + 2 - j1)
        j2 = math.floor(t2_lo_all / delta) - 1
        n2 = bucket(math.ceil(t2_hi_all / delta) + 2 - j2)
        arrays.update(row2=det_rows, l2=scene.wall.albedo / math.pi * det.weight / det.area,
                      j1=np.array(j1), j2=np.array(j2), shift=np.array(j1 + j2 - grid.first_bin * grid.oversample))
        fft_len = n1 + n2
        static = ObjectStatic("lambertian", 0, 0, False, len(obj_zones), n1=n1, n2=n2, fft_len=fft_len)
        paths = m * (len(flash) + len(det))
        what = f"Lambertian (albedo {_albedo_range(obj_list, part)})" if part else "Lambertian"
        how = (f"{what}, {m} surface samples on {n_vis} of {n_faces} faces; illumination leg {m} x {len(flash)} "
               f"wall cells, detection leg {m} x {len(det)} zone cells, legs convolved in time")
    notes.insert(0, (True, label, how))
    if n_hidden:
        notes.append((True, f"{label}: back faces", f"pruning off: {n_hidden} extra samples on faces that cannot see the wall"))
    elif n_vis < int((obj.mesh.face_areas > 0).sum()):
        notes.append((False, f"{label}: back faces",
                      f"{int((obj.mesh.face_areas > 0).sum()) - n_vis} faces cannot see the wall in any pose"))
    static, near_index = _pad_cells(static, arrays, near_index)
    return ObjectPlan(static=static, arrays=arrays, zone_rows=zone_rows, paths=paths, samples=samples,
                      mesh_index=mesh_index, near_index=near_index), notes


#: Per-cell arrays of each leg; ``c{leg}t`` is (3, N), the others have the cell axis first.
_LEG_KEYS = {"1": ("k1", "a1", "r1", "thr1", "l1", "recv", "uv", "jac", "frac", "box1", "cell_row"), "2": ("k2", "a2", "r2", "thr2", "l2", "row2", "box2")}
#: Wall-cell counts are padded to a multiple of this, near blocks to a multiple of NEAR_BUCKET (4: the exact
#: polygon coupling of a near pair is the costliest per pair, and blocks of 16 computed 3x the needed pairs for
#: DENALI's mount, up to 5 cells a scene; batches of other sizes still share programs through ``pad_to``).
CELL_BUCKET = 32
NEAR_BUCKET = 4


def _pad_cells(static: ObjectStatic, arrays: dict, near_index: dict) -> tuple[ObjectStatic, dict]:
    """Pad each leg's cells with weightless copies, and the near blocks, to bucket sizes.

    Scenes of a sweep (positions, objects) then share array shapes, so JAX
    reuses one compiled function; the padding contributes exactly nothing
    (zero radiance ``l``, zero receive factor, zero lobe share, threshold 0).
    Near-cell index lists are padded with the out-of-range index ``N``.
    """
    near, padded = {}, {}
    for leg in ("1", "2"):
        if f"c{leg}t" not in arrays:
            near[leg] = 0
            continue
        n = arrays[f"c{leg}t"].shape[1]
        size = max(CELL_BUCKET, -(-n // CELL_BUCKET) * CELL_BUCKET)
        pad = size - n
        arrays[f"c{leg}t"] = np.concatenate([arrays[f"c{leg}t"], np.repeat(arrays[f"c{leg}t"][:, -1:], pad, 1)], 1)
        for key in _LEG_KEYS[leg]:
            if key in arrays:
                a = arrays[key]
                fill = np.zeros((pad,) + a.shape[1:], a.dtype) if key in ("l1", "l2", "recv", "frac", "thr1", "thr2") \
                    else np.repeat(a[-1:], pad, 0)
                arrays[key] = np.concatenate([a, fill])
        k = max(len(i) for i in near_index[leg])
        near[leg] = 0 if k == 0 else min(size, -(-k // NEAR_BUCKET) * NEAR_BUCKET)
        padded[leg] = [np.concatenate([i, np.full(near[leg] - len(i), size)]).astype(np.int64)
                       for i in near_index[leg]]
    return dataclasses.replace(static, near1=near["1"], near2=near["2"]), padded


def _albedo_range(obj_list: list[HiddenObject], part: str) -> str:
    """The diffuse albedo(s) of a diffuse-base term over the batch, as text."""
    vals = sorted({o.diffuse_albedo for o in obj_list})
    return f"{vals[0]:g}" if len(vals) == 1 else f"{vals[0]:g}..{vals[-1]:g}"


def _zone_names(zones: list[int], sensor: SensorConfig, limit: int = 8) -> str:
    names = [f"({z // sensor.zones_cols},{z % sensor.zones_cols})" for z in zones[:limit]]
    return ", ".join(names) + (f" and {len(zones) - limit} more" if len(zones) > limit else "")
