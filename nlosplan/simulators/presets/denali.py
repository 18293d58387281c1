"""The DENALI capture rig (CVPR 2026) as a :class:`~nlosplan.simulators.scene.Scene`.

Sources
-------
Geometry, calibration and meshes are the public DENALI repository's
(github.com/NikhilBehari/denali, commit 9e1083293a4f6aac5e674c9bf0d948dc0697f8c3,
MIT licence), packaged in ``nlosplan/simulators/data/denali``. Placement
follows DENALI's own digital twin (``digitaltwin/scene.py``):

- LiDAR: the co-located camera of ``cameras.json`` (OpenCV extrinsic); the
  TMF8828 sits rigidly on the same mount and looks the same way.
- Relay wall: a 0.93 x 0.6096 m rectangle placed from wall tag 5.
- Tables: two 0.78 x 1.524 m rectangles placed from tags 14 and 15.
- Object at gantry position ``p``: ``T(tag 1 at p) . Rx(-90 deg) .
  translate(0, -0.005, -0.04)`` (the mount's y-up to z-up turn and offset),
  with tag 1's averaged pose from ``poses.json``. The mesh's -z face then
  looks at the wall from about 0.3 m.

World frame: the tracking rig's, metres, z up; tables at z ~ 0, relay wall
near y ~ 0.80, LiDAR at (0.459, 0.321, 0.373).

Localization labels
-------------------
:func:`positions_xy` returns DENALI's localization labels
(``tag1_positions.json``, what its benchmark regresses). They sit a nearly
constant (0.038, 0.028) m (in x, y) from the averaged tag-1 poses that place
the mesh; both are kept as published.

Mount
-----
The object mount (``object_mount.obj``, a 7.6 x 7.5 cm post from the table
up to the object) and its plate (``object_mount_plate.obj``, with tag 1 on
it) move with the gantry. DENALI's twin places the plate at ``T(tag 1) .
Rx(-90 deg)`` and the mount at the object's pose, both diffuse 0.8 (its
``PARTS_REFL``, visual pass only). :func:`mount_mesh` merges the two in
separate objects. DENALI names the post "object mount", so its background
capture ``NOOBJECTMOUNT`` most likely has no mount and ``NOOBJECT`` the
bare mount: the mount is a fixture (kept in the background) by default.

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

import json
import math
from functools import lru_cache
from importlib import resources
from typing import Any

import numpy as np

from nlosplan.errors import UserError
from nlosplan.simulators.meshes import load_obj
from nlosplan.simulators.scene import HiddenObject, LidarPose, Mesh, Rect, Scene, rigid_transform

__all__ = [
    "CLASS_GROUPS", "DENALI_OBJECTS", "N_POSITIONS", "SIZES", "class_group", "denali_scene",
    "mount_mesh", "object_mesh", "object_pose", "plate_mesh", "plate_pose", "positions_xy", "rig",
]

CLASS_GROUPS: dict[str, tuple[str, ...]] = {
    "numbers": tuple(str(d) for d in range(10)),
    "letters": ("A", "B", "C", "D", "E", "I", "O", "S", "U", "V"),
    "shapes": ("circle", "downarrow", "hexagon", "minus", "plus", "semicircle", "square", "triangle", "uparrow",
               "widerectangle"),
}
DENALI_OBJECTS: tuple[str, ...] = sum(CLASS_GROUPS.values(), ())
SIZES: tuple[str, ...] = ("4in", "8in")
N_POSITIONS = 100

_ALIASES = {"i": "I"}
WALL_SIZE = (0.93, 0.6096)  # along tag-5 x, along tag-5 y (metres)
TABLE_SIZE = (0.78, 1.524)  # along tag x, along tag y (metres)
_TAG_MARGIN = 0.068 / 2  # half the wall tags' printed size (metres)
_WALL_TAG_DROP = 0.186  # tag 5 above the wall's bottom edge (metres)
_MOUNT_OFFSET = (0.0, -0.005, -0.04)  # object/mount frame offset from tag 1 (metres)
MOUNT_ALBEDO = 0.8  # DENALI twin's PARTS_REFL (diffuse) for the mount and plate


def _data():
    return resources.files("nlosplan.simulators") / "data" / "denali"


@lru_cache(maxsize=None)
def _json(name: str) -> dict:
    return json.loads((_data() / name).read_text(encoding="utf-8"))


def _tag(pose: dict) -> np.ndarray:
    """4x4 world-from-tag transform of a ``poses.json`` entry."""
    return rigid_transform(pose["rotation_matrix"], pose["center"])


def _load_packaged(relpath: str, name: str) -> Mesh:
    with resources.as_file(_data().joinpath(*relpath.split("/"))) as path:
        return load_obj(path, name=name)


def _check_object(obj: Any) -> str:
    name = _ALIASES.get(obj, obj) if isinstance(obj, str) else obj
    if name not in DENALI_OBJECTS:
        raise UserError(f"unknown DENALI object {obj!r}; allowed: {', '.join(DENALI_OBJECTS)} ('i' = 'I')")
    return name


def _check_size(size: Any) -> str:
    if size not in SIZES:
        raise UserError(f"unknown DENALI object size {size!r}; allowed: {', '.join(SIZES)}")
    return size


def _check_position(position: Any) -> int:
    if isinstance(position, bool) or not isinstance(position, (int, np.integer)) or not 0 <= position < N_POSITIONS:
        raise UserError(f"DENALI position={position!r} is not allowed; allowed: integers 0 to {N_POSITIONS - 1}")
    return int(position)


def class_group(obj: str) -> str:
    """Class group of a DENALI object: ``"numbers"``, ``"letters"`` or ``"shapes"``."""
    name = _check_object(obj)
    return next(g for g, names in CLASS_GROUPS.items() if name in names)


@lru_cache(maxsize=None)
def _object_mesh(name: str, size: str) -> Mesh:
    stem = f"i_{size}" if (name == "I" and size == "4in") else f"{name}_{size}"
    return _load_packaged(f"objects/{stem}.obj", name=f"{name}_{size}")


def object_mesh(obj: str, size: str) -> Mesh:
    """Mesh of a DENALI object in the object-mount frame (metres).

    Parameters
    ----------
    obj : str
        One of :data:`DENALI_OBJECTS` (``"i"`` is accepted for ``"I"``).
    size : {"4in", "8in"}

    Returns
    -------
    Mesh
        The 3D-printed object, 6.6-7.6 mm thick along mesh z; its -z face
        looks at the relay wall once placed by :func:`object_pose`.
    """
    return _object_mesh(_check_object(obj), _check_size(size))


@lru_cache(maxsize=None)
def mount_mesh() -> Mesh:
    """Mesh of the object mount (the 33 cm post from the table up to the object), metres, object frame.

    Place it with :func:`object_pose`.
    """
    return _load_packaged("object_mount.obj", name="object_mount")


@lru_cache(maxsize=None)
def plate_mesh() -> Mesh:
    """Mesh of the mount plate (8 x 8 x 1 cm, tag 1 on it), metres, in tag 1's z-up frame.

    Place it with :func:`plate_pose`. It overlaps the top of the post, so it
    is a separate object (the twin renders overlapping meshes apart).
    """
    return _load_packaged("object_mount_plate.obj", name="object_mount_plate")


@lru_cache(maxsize=None)
def _object_poses() -> np.ndarray:
    a = -math.pi / 2  # DENALI's y-up to z-up turn about x
    rx = rigid_transform([[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]])
    offset = rigid_transform(translation=_MOUNT_OFFSET)
    poses = _json("poses.json")["tracking_tag1_index_avgposes"]
    out = np.stack([_tag(poses[str(p)]) @ rx @ offset for p in range(N_POSITIONS)])
    out.setflags(write=False)
    return out


def plate_pose(position: int) -> np.ndarray:
    """Pose of the mount plate (tag 1's frame turned z-up) at a gantry position, shape (4, 4).

    ``object_pose(p) @ inv(translate(0, -0.005, -0.04))``: what DENALI's twin uses for the plate.
    """
    return object_pose(position) @ rigid_transform(translation=-np.asarray(_MOUNT_OFFSET))


def object_pose(position: int) -> np.ndarray:
    """Object-to-world transform at a gantry position.

    Parameters
    ----------
    position : int
        Gantry position index, 0 to 99.

    Returns
    -------
    ndarray of float64, shape (4, 4)
        ``T(tag 1) . Rx(-90 deg) . translate(0, -0.005, -0.04)`` (metres).
    """
    return np.array(_object_poses()[_check_position(position)])


@lru_cache(maxsize=None)
def _labels() -> np.ndarray:
    raw = _json("tag1_positions.json")
    out = np.array([raw[f"frame{p}_tag1"] for p in range(N_POSITIONS)], dtype=np.float64)
    out.setflags(write=False)
    return out


def positions_xy() -> np.ndarray:
    """DENALI's localization labels: world (x, y) of tag 1 per position, shape (100, 2), metres."""
    return np.array(_labels()[:, :2])


def _wall(tags: dict, albedo: float) -> Rect:
    t5 = _tag(tags["5"])
    x = t5[:3, 0] / np.linalg.norm(t5[:3, 0])
    y = t5[:3, 1] / np.linalg.norm(t5[:3, 1])
    width, height = WALL_SIZE
    center = t5[:3, 3] + (width / 2 - _TAG_MARGIN) * x + (height / 2 - _TAG_MARGIN - _WALL_TAG_DROP) * y
    lit = -np.cross(x, y)
    # u = x, v = -y gives u x v = -(x x y), the lit normal, with v pointing up in the world
    wall = Rect(center=center, u_axis=x, v_axis=-y, half_u=width / 2, half_v=height / 2,
                albedo=albedo, name="relay wall")
    if not np.allclose(wall.normal, lit / np.linalg.norm(lit), atol=1e-6):
        raise RuntimeError("packaged DENALI wall tag gives an inconsistent wall normal")
    return wall


def _table(tags: dict, tag_id: str, albedo: float) -> Rect:
    t = _tag(tags[tag_id])
    x, y = t[:3, 0], t[:3, 1]
    z = -np.cross(x, y)
    sx, sy = TABLE_SIZE
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
    cam = _json("cameras.json")["COLOCATED_CAMERA"]
    lidar = LidarPose.from_opencv(cam["position"], cam["rotation_matrix"])
    tags = _json("poses.json")["tracking_avgposes"]
    planes = (_table(tags, "14", table_albedo), _table(tags, "15", table_albedo)) if tables else ()
    return lidar, _wall(tags, wall_albedo), planes


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
        One of :data:`DENALI_OBJECTS` (``"i"`` is accepted for ``"I"``).
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
    name = _check_object(obj)
    size = _check_size(size)
    p = _check_position(position)
    on = _check_lights(lights)
    lidar, wall, planes = rig(wall_albedo=wall_albedo, table_albedo=table_albedo, tables=tables)
    pose = _object_poses()[p]
    objects = [HiddenObject(mesh=object_mesh(name, size), to_world=pose, reflectance=reflectance,
                            albedo=albedo, lobe_fwhm_deg=lobe_fwhm_deg, name=f"{name}_{size}",
                            diffuse_albedo=diffuse_albedo)]
    if not isinstance(mount, (bool, np.bool_)) or not isinstance(mount_in_background, (bool, np.bool_)):
        raise UserError("mount and mount_in_background must be true or false")
    if mount:
        for mesh, to_world, label in ((mount_mesh(), pose, "object mount"), (plate_mesh(), plate_pose(p), "mount plate")):
            objects.append(HiddenObject(mesh=mesh, to_world=to_world, reflectance="lambertian", albedo=mount_albedo,
                                        name=label, fixture=bool(mount_in_background)))
    xy = _labels()[p, :2]
    meta = {
        "preset": "denali", "object": name, "size": size, "position": p, "class_group": class_group(name),
        "lights": "on" if on else "off", "object_xy": [float(xy[0]), float(xy[1])], "reflectance": reflectance,
        "albedo": objects[0].albedo, "lobe_fwhm_deg": objects[0].lobe_fwhm_deg,
        "diffuse_albedo": objects[0].diffuse_albedo, "mount": bool(mount),
        **({"mount_albedo": objects[1].albedo, "mount_in_background": bool(mount_in_background)} if mount else {}),
        "wall_albedo": wall.albedo, "tables": bool(tables),
    }
    return Scene(lidar=lidar, wall=wall, planes=planes, objects=tuple(objects), lights_on=on,
                 name=f"denali {name}_{size} p{p:02d} lights {meta['lights']}", meta=meta)
