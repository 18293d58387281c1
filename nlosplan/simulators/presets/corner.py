"""A parametric corner: a LiDAR facing a relay wall, a hidden object beside it.

Frame: metres, z up. The relay wall lies in the plane y = 0, centred at the
origin, width along x, height along z, lit normal (0, -1, 0). The LiDAR sits
at (0, -wall_distance, 0) looking along +y with up +z, so +x is its right.
An object at ``object_xy = (x, y)`` has its centre at (x, -y, 0): ``x``
lateral, ``y`` its distance in front of the wall.

Object orientation
------------------
- ``"patch"``: :func:`~nlosplan.simulators.meshes.square_patch` turned so its
  normal (mesh +z) points at the wall (+y world).
- Any other mesh (a :class:`Mesh`, an ``.obj`` path, a DENALI name such as
  ``"A_8in"``): DENALI's mount convention, mesh +z to world -y and mesh +y
  to world +z, so the mesh's -z face looks at the wall; the mesh origin is
  placed at the object centre.

``yaw_deg`` then turns the object about the vertical axis through its centre.
"""

from __future__ import annotations

import math
import os
from typing import Any

import numpy as np

from nlosplan.denali.rig import ALIASES, DENALI_OBJECTS, SIZES
from nlosplan.errors import UserError
from nlosplan.schema import check_quantity
from nlosplan.simulators.meshes import load_obj, square_patch
from nlosplan.simulators.presets.denali import object_mesh
from nlosplan.simulators.scene import HiddenObject, LidarPose, Mesh, Rect, Scene, rigid_transform

__all__ = ["corner_scene"]

# mesh frame -> world (columns are the world images of mesh x, y, z)
_PATCH_TO_WALL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])  # +z -> +y, +y -> -z
_DENALI_TO_WALL = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])  # +z -> -y, +y -> +z
FLOOR_SIZE = 3.0  # metres, square
FLOOR_ALBEDO = 0.3


def _number(name: str, value: Any, *, positive: bool = False, quantity: str = "scene_m") -> float:
    """A finite number within its physical range (:data:`nlosplan.schema.QUANTITIES`: metres within 100 m)."""
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)) or not math.isfinite(
        value
    ):
        raise UserError(f"{name}={value!r} must be a finite number")
    if positive and value <= 0:
        raise UserError(f"{name}={value!r} must be > 0 (metres)")
    return check_quantity(quantity, float(value), name)


def _pair(name: str, value: Any) -> tuple[float, float]:
    try:
        a, b = value
    except (TypeError, ValueError):
        raise UserError(f"{name}={value!r} must be two numbers") from None
    return _number(f"{name}[0]", a), _number(f"{name}[1]", b)


def _object_mesh(obj: Any, size: float) -> tuple[Mesh, np.ndarray, str]:
    """Mesh, mesh-to-world rotation (before yaw) and label of the ``object`` argument."""
    if isinstance(obj, Mesh):
        return obj, _DENALI_TO_WALL, obj.name
    if isinstance(obj, os.PathLike) or (isinstance(obj, str) and obj.lower().endswith(".obj")):
        mesh = load_obj(obj)
        return mesh, _DENALI_TO_WALL, mesh.name
    if obj == "patch":
        return square_patch(size), _PATCH_TO_WALL, "patch"
    if isinstance(obj, str) and "_" in obj:
        name, sz = obj.rsplit("_", 1)
        known = ALIASES.get(name, name) in DENALI_OBJECTS and sz in SIZES
        if known:
            mesh = object_mesh(name, sz)
            return mesh, _DENALI_TO_WALL, mesh.name
    raise UserError(
        f"object={obj!r} is not allowed; allowed: 'patch', a Mesh, a path to an .obj file, "
        f"or a DENALI name '<object>_<4in|8in>' such as 'A_8in'"
    )


def corner_scene(*, wall_distance: float = 0.5, object_xy=(0.45, 0.30), object: Any = "patch",
                 object_size: float = 0.10, reflectance: str = "lambertian", albedo: float = 0.5,
                 lobe_fwhm_deg: float = 2.0, lights_on: bool = False, wall_size=(1.2, 0.8),
                 wall_albedo: float = 0.8, yaw_deg: float = 0.0, floor_z: float | None = None,
                 diffuse_albedo: float = 0.0) -> Scene:
    """A generic corner scene.

    Parameters
    ----------
    wall_distance : float
        LiDAR to relay wall along the optical axis, metres (> 0).
    object_xy : (float, float)
        Object centre: lateral x (+x is the LiDAR's right) and distance y in
        front of the wall (> 0), metres; the centre is at (x, -y, 0).
    object : "patch", Mesh, path or str
        The hidden object: a square patch facing the wall, a mesh, an
        ``.obj`` file, or a DENALI name like ``"A_8in"`` (see the module notes
        for the orientation).
    object_size : float
        Side of the patch, metres (> 0; used by ``"patch"`` only).
    reflectance : {"retroreflective", "lambertian"}
    albedo : float
        Object albedo in [0, 1].
    lobe_fwhm_deg : float
        Retroreflective lobe FWHM, degrees.
    lights_on : bool
        Room lights.
    wall_size : (float, float)
        Relay wall width (x) and height (z), metres (> 0).
    wall_albedo : float
        Relay wall albedo in [0, 1].
    yaw_deg : float
        Turn of the object about the vertical axis through its centre,
        degrees (positive: counter-clockwise seen from above).
    floor_z : float, optional
        Add a 3 x 3 m floor (albedo 0.3, lit side up) at this height, metres
        (below the LiDAR: < 0). The floor spans y from -3 m to the wall.
    diffuse_albedo : float
        Lambertian base of a retroreflective object (0: none; ``albedo +
        diffuse_albedo <= 1``).

    Returns
    -------
    Scene
        ``meta`` holds ``preset`` ("corner"), ``object``, ``object_xy``,
        ``wall_distance`` and ``reflectance``.

    Raises
    ------
    UserError
        A non-positive distance or size, or an unknown object (one line).

    Examples
    --------
    >>> scene = corner_scene(wall_distance=0.5, object_xy=(0.3, 0.2))
    >>> scene.objects[0].to_world[:3, 3].tolist()
    [0.3, -0.2, 0.0]
    """
    d = _number("wall_distance", wall_distance, positive=True)
    x, y = _pair("object_xy", object_xy)
    if y <= 0:
        raise UserError(f"object_xy y={y!r} must be > 0 (the object's distance in front of the wall, metres)")
    size = _number("object_size", object_size, positive=True)
    width, height = _pair("wall_size", wall_size)
    if width <= 0 or height <= 0:
        raise UserError(f"wall_size={(width, height)!r} must be two lengths > 0 (metres)")
    yaw = math.radians(_number("yaw_deg", yaw_deg, quantity="angle_deg"))
    if not isinstance(lights_on, (bool, np.bool_)):
        raise UserError(f"lights_on={lights_on!r} must be true or false")

    wall = Rect(center=(0.0, 0.0, 0.0), u_axis=(1.0, 0.0, 0.0), v_axis=(0.0, 0.0, 1.0),
                half_u=width / 2, half_v=height / 2, albedo=wall_albedo, name="relay wall")
    lidar = LidarPose.look_at((0.0, -d, 0.0), (0.0, 0.0, 0.0), up_hint=(0.0, 0.0, 1.0))

    mesh, orient, label = _object_mesh(object, size)
    c, s = math.cos(yaw), math.sin(yaw)
    rz = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    to_world = rigid_transform(rz @ orient, (x, -y, 0.0))
    hidden = HiddenObject(mesh=mesh, to_world=to_world, reflectance=reflectance, albedo=albedo,
                          lobe_fwhm_deg=lobe_fwhm_deg, name=label, diffuse_albedo=diffuse_albedo)

    planes: tuple[Rect, ...] = ()
    if floor_z is not None:
        fz = _number("floor_z", floor_z)
        if fz >= 0:
            raise UserError(f"floor_z={fz!r} must be below the LiDAR (< 0 metres)")
        planes = (Rect.facing((0.0, -FLOOR_SIZE / 2, fz), (0.0, 0.0, 1.0), (0.0, 1.0, 0.0), width=FLOOR_SIZE,
                              height=FLOOR_SIZE, albedo=FLOOR_ALBEDO, name="floor"),)

    meta = {"preset": "corner", "object": label, "object_xy": [x, y], "wall_distance": d, "reflectance": reflectance,
            "albedo": hidden.albedo, "lobe_fwhm_deg": hidden.lobe_fwhm_deg, "diffuse_albedo": hidden.diffuse_albedo,
            "object_yaw_deg": float(yaw_deg),
            "object_size": float(object_size), "lights": "on" if lights_on else "off"}
    return Scene(lidar=lidar, wall=wall, planes=planes, objects=(hidden,), lights_on=bool(lights_on),
                 name=f"corner {label} at ({x:g}, {y:g}) m", meta=meta)
