"""The DENALI capture rig (CVPR 2026) as a :class:`~nlosplan.simulators.scene.Scene`.

The rig's facts (objects, sizes, class groups, tag poses, object poses per
gantry position, localization labels, wall and table placement constants,
the gantry in millimetres) live in :mod:`nlosplan.denali`, with the packaged
DENALI files and their sources; this module turns them into scenes: the
LiDAR from the co-located camera, the relay wall from tag 5, the tables from
tags 14 and 15, the object meshes (loaded by :mod:`nlosplan.simulators.meshes`)
at their poses.

Mount
-----
The object mount (``object_mount.obj``, a 7.6 x 7.5 cm post from the table
up to the object) and its plate (``object_mount_plate.obj``, with tag 1 on
it) move with the gantry. DENALI's twin places the plate at ``T(tag 1) .
Rx(-90 deg)`` and the mount at the object's pose, both diffuse 0.8 (its
``PARTS_REFL``, visual pass only). ``mount=True`` adds the two as separate
objects (the plate overlaps the post). DENALI names the post "object mount",
so its background capture ``NOOBJECTMOUNT`` most likely has no mount and
``NOOBJECT`` the bare mount: the mount is a fixture (kept in the background)
by default.

Assumptions (to be calibrated against captures)
-----------------------------------------------
- Object albedo 0.5 and a 2 deg FWHM retroreflective lobe, no diffuse base
  (DENALI's Table 2 cannot separate a diffuse base from the retroreflective
  part: see ``docs/scene-physics.md``).
- Relay-wall albedo 0.8 and table albedo 0.5 (the twin's table colour is
  (0.6, 0.5, 0.4)); the mount and plate are Lambertian with albedo 0.8.
- The TMF8828 zone grid looks like the co-located camera image: sensor
  right = camera x, up = -camera y, zone row 0 at the top of the image.
"""

from __future__ import annotations

from functools import lru_cache
from importlib import resources
from typing import Any

import numpy as np

from nlosplan import denali
from nlosplan.errors import UserError
from nlosplan.simulators.meshes import load_obj
from nlosplan.simulators.scene import HiddenObject, LidarPose, Mesh, Rect, Scene

__all__ = ["MOUNT_ALBEDO", "denali_scene", "mount_mesh", "object_mesh", "plate_mesh", "rig", "scene_at"]

MOUNT_ALBEDO = 0.8  # DENALI twin's PARTS_REFL (diffuse) for the mount and plate


def _load_packaged(relpath: str, name: str) -> Mesh:
    with resources.as_file(denali.data_dir().joinpath(*relpath.split("/"))) as path:
        return load_obj(path, name=name)


@lru_cache(maxsize=None)
def _object_mesh(name: str, size: str) -> Mesh:
    stem = f"i_{size}" if (name == "I" and size == "4in") else f"{name}_{size}"
    return _load_packaged(f"objects/{stem}.obj", name=f"{name}_{size}")


def object_mesh(obj: str, size: str) -> Mesh:
    """Mesh of a DENALI object in the object-mount frame (metres).

    Parameters
    ----------
    obj : str
        One of :data:`nlosplan.denali.DENALI_OBJECTS` (``"i"`` is accepted for ``"I"``).
    size : {"4in", "8in"}

    Returns
    -------
    Mesh
        The 3D-printed object, 6.6-7.6 mm thick along mesh z; its -z face
        looks at the relay wall once placed by :func:`nlosplan.denali.object_pose`.
    """
    return _object_mesh(denali.check_object(obj), denali.check_size(size))


@lru_cache(maxsize=None)
def mount_mesh() -> Mesh:
    """Mesh of the object mount (the 33 cm post from the table up to the object), metres, object frame.

    Place it with :func:`nlosplan.denali.object_pose`.
    """
    return _load_packaged("object_mount.obj", name="object_mount")


@lru_cache(maxsize=None)
def plate_mesh() -> Mesh:
    """Mesh of the mount plate (8 x 8 x 1 cm, tag 1 on it), metres, in tag 1's z-up frame.

    Place it with :func:`nlosplan.denali.plate_pose`. It overlaps the top of
    the post, so it is a separate object (the twin renders overlapping
    meshes apart).
    """
    return _load_packaged("object_mount_plate.obj", name="object_mount_plate")


def _wall(albedo: float) -> Rect:
    t5 = denali.tag_pose("5")
    x = t5[:3, 0] / np.linalg.norm(t5[:3, 0])
    y = t5[:3, 1] / np.linalg.norm(t5[:3, 1])
    width, height = denali.WALL_SIZE
    margin = denali.WALL_TAG_MARGIN
    center = t5[:3, 3] + (width / 2 - margin) * x + (height / 2 - margin - denali.WALL_TAG_DROP) * y
    lit = -np.cross(x, y)
    # u = x, v = -y gives u x v = -(x x y), the lit normal, with v pointing up in the world
    wall = Rect(center=center, u_axis=x, v_axis=-y, half_u=width / 2, half_v=height / 2,
                albedo=albedo, name="relay wall")
    if not np.allclose(wall.normal, lit / np.linalg.norm(lit), atol=1e-6):
        raise RuntimeError("packaged DENALI wall tag gives an inconsistent wall normal")
    return wall


def _table(tag_id: str, albedo: float) -> Rect:
    t = denali.tag_pose(tag_id)
    x, y = t[:3, 0], t[:3, 1]
    z = -np.cross(x, y)
    sx, sy = denali.TABLE_SIZE
    pos = t[:3, 3] - 0.001 * z
    if tag_id == "14":
        pos = pos + sx / 2 * x - sy / 2 * y - 0.04 * x + 0.548 * y
    else:
        pos = pos - sx / 2 * x - sy / 2 * y + 0.04 * x + 0.548 * y
    if abs(z[2]) < 0.9:
        raise RuntimeError(f"packaged DENALI table tag {tag_id} is not horizontal")
    # u = x, v = -y gives u x v = z; flip v if z points down, so the lit side faces up
    v = -y if z[2] > 0 else y
    return Rect(center=pos, u_axis=x, v_axis=v, half_u=sx / 2, half_v=sy / 2, albedo=albedo, name=f"table {tag_id}")


@lru_cache(maxsize=None)
def _rig(wall_albedo: float, table_albedo: float, tables: bool) -> tuple[LidarPose, Rect, tuple[Rect, ...]]:
    position, rotation = denali.camera_pose()
    lidar = LidarPose.from_opencv(position, rotation)
    planes = (_table("14", table_albedo), _table("15", table_albedo)) if tables else ()
    return lidar, _wall(wall_albedo), planes


def rig(*, wall_albedo: float = 0.8, table_albedo: float = 0.5,
        tables: bool = True) -> tuple[LidarPose, Rect, tuple[Rect, ...]]:
    """The fixed part of the DENALI rig: LiDAR, relay wall and tables.

    Parameters
    ----------
    wall_albedo, table_albedo : float
        Lambertian albedos in [0, 1] (assumed, see the module notes).
    tables : bool
        Include the two tables.

    Returns
    -------
    lidar : LidarPose
    wall : Rect
        0.93 x 0.6096 m, lit normal towards the LiDAR (about -y world).
    tables : tuple of Rect
        Zero or two 0.78 x 1.524 m rectangles, lit side up, at z ~ 0.
    """
    for nm, val in (("wall_albedo", wall_albedo), ("table_albedo", table_albedo)):
        if isinstance(val, bool) or not isinstance(val, (int, float, np.integer, np.floating)) or not 0 <= val <= 1:
            raise UserError(f"{nm}={val!r} is out of range; allowed: 0 to 1")
    return _rig(float(wall_albedo), float(table_albedo), bool(tables))


def _check_lights(lights: Any) -> bool:
    if isinstance(lights, (bool, np.bool_)):
        return bool(lights)
    if isinstance(lights, str) and lights.lower() in ("on", "off"):
        return lights.lower() == "on"
    raise UserError(f"lights={lights!r} is not allowed; allowed: 'on', 'off', True, False")


def denali_scene(obj: str = "A", size: str = "8in", position: int = 19, lights: str | bool = "off", *,
                 reflectance: str = "retroreflective", albedo: float = 0.5, lobe_fwhm_deg: float = 2.0,
                 diffuse_albedo: float = 0.0, mount: bool = False, mount_albedo: float = MOUNT_ALBEDO,
                 mount_in_background: bool = True, wall_albedo: float = 0.8, table_albedo: float = 0.5,
                 tables: bool = True) -> Scene:
    """One DENALI capture as a scene.

    Parameters
    ----------
    obj : str
        One of :data:`nlosplan.denali.DENALI_OBJECTS` (``"i"`` is accepted for ``"I"``).
    size : {"4in", "8in"}
    position : int
        Gantry position index, 0 to 99.
    lights : {"on", "off"} or bool
        Room lights.
    reflectance : {"retroreflective", "lambertian"}
        Object reflectance model; ``albedo`` and ``lobe_fwhm_deg`` (degrees)
        are its parameters (assumed values by default).
    diffuse_albedo : float
        Lambertian base of a retroreflective object (0: pure retroreflector;
        ``albedo + diffuse_albedo <= 1``).
    mount : bool
        Add the object mount and its plate (:func:`mount_mesh`,
        :func:`plate_mesh`, Lambertian) as two more objects that move with
        the gantry.
    mount_albedo : float
        The mount's Lambertian albedo (DENALI's twin: 0.8).
    mount_in_background : bool
        The mount is a fixture that stays in the background capture (DENALI's
        NOOBJECT with the bare mount: it cancels from the signal); False
        leaves it in the signal (a background without the mount).
    wall_albedo, table_albedo : float
        Relay-wall and table albedos.
    tables : bool
        Include the two tables as first-bounce planes.

    Returns
    -------
    Scene
        ``meta`` holds ``preset``, ``object``, ``size``, ``position``,
        ``class_group``, ``lights`` ("on"/"off"), ``object_xy`` (the
        localization label, metres) and ``reflectance``.

    Raises
    ------
    UserError
        Unknown object or size, a position outside 0..99, or bad parameters.

    Examples
    --------
    >>> scene = denali_scene("A", "8in", position=19, lights="off")
    >>> scene.meta["class_group"]
    'letters'
    """
    name = denali.check_object(obj)
    size = denali.check_size(size)
    p = denali.check_position(position)
    on = _check_lights(lights)
    lidar, wall, planes = rig(wall_albedo=wall_albedo, table_albedo=table_albedo, tables=tables)
    pose = denali.object_poses()[p]
    objects = [HiddenObject(mesh=object_mesh(name, size), to_world=pose, reflectance=reflectance,
                            albedo=albedo, lobe_fwhm_deg=lobe_fwhm_deg, name=f"{name}_{size}",
                            diffuse_albedo=diffuse_albedo)]
    if not isinstance(mount, (bool, np.bool_)) or not isinstance(mount_in_background, (bool, np.bool_)):
        raise UserError("mount and mount_in_background must be true or false")
    if mount:
        for mesh, to_world, label in ((mount_mesh(), pose, "object mount"),
                                      (plate_mesh(), denali.plate_pose(pose), "mount plate")):
            objects.append(HiddenObject(mesh=mesh, to_world=to_world, reflectance="lambertian", albedo=mount_albedo,
                                        name=label, fixture=bool(mount_in_background), support=True))
    xy = denali.tag1_positions()[p, :2]
    meta = {
        "preset": "denali", "object": name, "size": size, "position": p, "class_group": denali.class_group(name),
        "lights": "on" if on else "off", "object_xy": [float(xy[0]), float(xy[1])], "reflectance": reflectance,
        "albedo": objects[0].albedo, "lobe_fwhm_deg": objects[0].lobe_fwhm_deg,
        "diffuse_albedo": objects[0].diffuse_albedo, "mount": bool(mount),
        **({"mount_albedo": objects[1].albedo, "mount_in_background": bool(mount_in_background)} if mount else {}),
        "wall_albedo": wall.albedo, "tables": bool(tables),
    }
    return Scene(lidar=lidar, wall=wall, planes=planes, objects=tuple(objects), lights_on=on,
                 name=f"denali {name}_{size} p{p:02d} lights {meta['lights']}", meta=meta)


def scene_at(obj: str, size: str, x_mm: float, y_mm: float, lights: str = "off", **scene_kw):
    """The DENALI scene with the object at gantry (x, y) mm (any point, not only the grid).

    Parameters
    ----------
    obj, size, lights, **scene_kw
        As :func:`denali_scene` (keyword arguments: reflectance, albedos, mount, ...).
    x_mm, y_mm : float
        Gantry position, millimetres.

    Returns
    -------
    Scene
        ``meta`` has ``position`` (the grid index, or -1 off the grid),
        ``object_xy`` (:func:`nlosplan.denali.geometry.label_xy`) and ``gantry_mm``.
    """
    base = denali_scene(obj, size, 0, lights, **scene_kw)
    pose = denali.object_pose_mm(x_mm, y_mm)
    plate = denali.plate_pose(pose)
    meta = {**base.meta, "position": denali.grid_index(x_mm, y_mm), "object_xy": list(denali.label_xy(x_mm, y_mm)),
            "gantry_mm": [float(x_mm), float(y_mm)]}
    moved = tuple(o.moved_to(plate if o.name == "mount plate" else pose) for o in base.objects)
    return base.replace(objects=moved, meta=meta,
                        name=f"denali {base.objects[0].name} at ({float(x_mm):.1f}, {float(y_mm):.1f}) mm")
