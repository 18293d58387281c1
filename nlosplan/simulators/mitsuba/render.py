"""Mitsuba scene dictionaries of the twin, and one render -> film transient.

The relay wall carries the twin's meter (``nlosplan_point_meter``, a
``nlos_capture_meter`` at the LiDAR whose film pixels are the wall points of
the zone sub-pixels); the hidden meshes are diffuse (Lambertian) or
``nlosplan_retro``; the flash is a ``projector`` at the LiDAR whose texture
is the sensor's flash profile; the integrator is mitransient's
``transient_nlos_path`` with hidden-geometry sampling, counting the first
(LiDAR -> wall) and last (wall -> LiDAR) legs in the path length. Other
planes of the scene (tables, floor) are not in the twin: like DENALI's twin
it measures the relay wall only.
"""

from __future__ import annotations

import math
import time
import uuid

import numpy as np

from nlosplan.errors import UserError
from nlosplan.simulators.mitsuba.geometry import Detection, FlashTexture
from nlosplan.simulators.mitsuba.plugins import POINT_SETS, vmf_kappa
from nlosplan.simulators.scene import HiddenObject, Scene

#: Path vertices the integrator follows (camera ray to x2, hidden object x, wall x1, then the flash).
MAX_DEPTH = 4
#: Mitsuba sampler of the path samples.
SAMPLER = "independent"


def _filter_bounces(three_bounce: bool, laser: bool) -> int:
    """mitransient's ``filter_bounces`` that keeps exactly the paths LiDAR -> x2 -> x -> x1 -> LiDAR.

    Its next-event estimation at depth ``d`` passes ``filter_depth = filter_bounces + 1``;
    x1 is at depth 2, and laser sampling counts the laser connection as one more.
    The direct wall return (depth 0) cannot be selected this way: it is rendered
    alone with ``max_depth = 2`` and no filter (-1).
    """
    if not three_bounce:
        return -1
    return 2 if laser else 1


def _transform(mi, columns) -> object:
    m = np.eye(4)
    m[:3, :4] = np.stack([np.asarray(c, dtype=np.float64) for c in columns], axis=1)
    return mi.ScalarTransform4f(m)


def _bsdf(obj: HiddenObject) -> dict:
    if obj.reflectance == "lambertian":
        return {"type": "diffuse", "reflectance": {"type": "rgb", "value": [obj.albedo] * 3}}
    if obj.lobe_fwhm_deg <= 0:
        raise UserError(f"object {obj.name!r}: the mitsuba backend needs a retroreflective lobe > 0 deg "
                        "(a mirror-exact retroreflector has no finite BSDF)")
    return {"type": "nlosplan_retro", "albedo": obj.albedo, "diffuse": obj.diffuse_albedo,
            "kappa": vmf_kappa(obj.lobe_fwhm_deg)}


def object_mesh(mi, obj: HiddenObject):
    """A Mitsuba mesh of a hidden object in the world frame (zero-area faces dropped)."""
    v = obj.world_vertices().astype(np.float32)
    keep = obj.mesh.face_areas > 1e-14
    f = obj.mesh.faces[keep].astype(np.uint32)
    if f.shape[0] == 0:
        raise UserError(f"object {obj.name!r} has no triangle of non-zero area")
    props = mi.Properties()
    props["bsdf"] = mi.load_dict(_bsdf(obj))
    mesh = mi.Mesh(obj.name or "object", v.shape[0], f.shape[0], props=props)
    params = mi.traverse(mesh)
    params["vertex_positions"] = v.ravel()
    params["faces"] = f.ravel()
    params.update()
    return mesh


def projector(mi, scene: Scene, texture: FlashTexture | None, aim=None) -> dict:
    """The flash (``texture``) or, with ``aim`` (a world point), a narrow unit-intensity laser at it."""
    lid = scene.lidar
    if aim is None:
        img = np.repeat(texture.image[..., None], 3, axis=-1)
        return {"type": "projector", "fov": texture.fov_x_deg,
                "irradiance": {"type": "bitmap", "bitmap": mi.Bitmap(img), "raw": True, "filter_type": "bilinear"},
                "to_world": _transform(mi, [-lid.right, lid.up, lid.forward, lid.position])}
    fwd = np.asarray(aim, dtype=np.float64) - lid.position
    fwd /= np.linalg.norm(fwd)
    up = lid.up - fwd * float(lid.up @ fwd)
    up /= np.linalg.norm(up)
    left = np.cross(up, fwd)
    img = np.full((8, 8, 3), 1.0 / math.pi, dtype=np.float32)  # intensity 1 on the axis
    return {"type": "projector", "fov": 0.5,
            "irradiance": {"type": "bitmap", "bitmap": mi.Bitmap(img), "raw": True, "filter_type": "nearest"},
            "to_world": _transform(mi, [left, up, fwd, lid.position])}


def scene_dict(mi, scene: Scene, det: Detection, axis: tuple[float, float, int], *, spp: int, three_bounce: bool,
               emitter: dict, laser: bool = False, objects=None) -> tuple[dict, str]:
    """The Mitsuba scene of one render; returns it and the key of its meter points in ``POINT_SETS``.

    ``three_bounce``: the three-bounce return of ``objects`` (default: all of
    the scene's hidden objects; hidden-geometry sampling at x2); otherwise
    the direct wall return alone (no objects).
    """
    wall = scene.wall
    key = uuid.uuid4().hex
    POINT_SETS[key] = det.points
    start, width, bins = axis
    integrator = {"type": "nlosplan_nlos_path", "temporal_filter": "box", "account_first_and_last_bounces": True,
                  "nlos_hidden_geometry_sampling": bool(three_bounce), "nlos_hidden_geometry_sampling_max_depth": 1,
                  "nlos_laser_sampling": bool(laser), "filter_bounces": _filter_bounces(three_bounce, laser),
                  "max_depth": MAX_DEPTH if three_bounce else 2, "rr_depth": 100}
    d = {
        "type": "scene",
        "integrator": integrator,
        "relay_wall": {
            "type": "rectangle",
            "to_world": _transform(mi, [wall.u_axis * wall.half_u, wall.v_axis * wall.half_v, wall.normal, wall.center]),
            "bsdf": {"type": "diffuse", "reflectance": {"type": "rgb", "value": [wall.albedo] * 3}},
            "sensor": {
                "type": "nlosplan_point_meter", "points_key": key, "shutter_open": 0.0, "shutter_close": 0.0, "sensor_origin": scene.lidar.position.tolist(),
                "film": {"type": "transient_hdr_film", "width": det.width, "height": det.height,
                         "temporal_bins": int(bins), "bin_width_opl": float(width), "start_opl": float(start),
                         "rfilter": {"type": "box"}},
                "sampler": {"type": SAMPLER, "sample_count": int(spp)},
            },
        },
        "flash": emitter,
    }
    if three_bounce:
        for k, obj in enumerate(scene.objects if objects is None else objects):
            d[f"hidden_{k:02d}"] = object_mesh(mi, obj)
    return d, key


def render(mi, d: dict, key: str, *, spp: int, seed: int) -> tuple[np.ndarray, float]:
    """Render a scene dictionary; the film's first channel as ``(H * W, T)`` float64, and the seconds it took."""
    t0 = time.perf_counter()
    try:
        scn = mi.load_dict(d)
        _, transient = mi.render(scn, spp=int(spp), seed=int(seed))
        arr = np.array(transient, dtype=np.float64)
    finally:
        POINT_SETS.pop(key, None)
    h, w, t = arr.shape[:3]
    return arr[..., 0].reshape(h * w, t), time.perf_counter() - t0
