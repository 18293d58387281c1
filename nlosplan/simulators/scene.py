"""Scenes for NLOS transport: LiDAR pose, relay wall, planes, hidden objects.

World frame: metres, right-handed, any orientation (the DENALI preset uses
its tracking rig's frame with z up). The sensor frame of
:mod:`nlosplan.sensor_models.zones` (x right, y up, z forward) is mapped to
the world by :class:`LidarPose`.

Every type here is frozen and validated on construction; invalid input
raises :class:`~nlosplan.errors.UserError` with one line naming the bad value.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import math
import warnings
from dataclasses import dataclass, field
from typing import Any, Mapping

import numpy as np

from nlosplan.errors import UserError

REFLECTANCES = ("retroreflective", "lambertian")


class NLOSWarning(UserWarning):
    """A scene that can be simulated but is probably not what the user meant."""


def _vec3(name: str, value: Any) -> np.ndarray:
    try:
        v = np.asarray(value, dtype=np.float64).reshape(3)
    except (TypeError, ValueError):
        raise UserError(f"{name}={value!r} must be three numbers (x, y, z) in metres") from None
    if not np.all(np.isfinite(v)):
        raise UserError(f"{name}={v.tolist()} must be finite")
    return v


def _unit(name: str, value: Any) -> np.ndarray:
    v = _vec3(name, value)
    n = float(np.linalg.norm(v))
    if n < 1e-12:
        raise UserError(f"{name}={v.tolist()} must be a non-zero direction")
    return v / n


def _readonly(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


# --------------------------------------------------------------------- LiDAR
@dataclass(frozen=True, eq=False)
class LidarPose:
    """Position and orientation of the flash LiDAR.

    Parameters
    ----------
    position : array_like, shape (3,)
        Optical centre, metres (emitter and receiver are co-located).
    right, up, forward : array_like, shape (3,)
        World directions of the sensor frame's x (right), y (up) and z
        (optical axis) axes. They are orthonormalised on construction
        (``forward`` kept, ``up`` made orthogonal to it, ``right`` completed).

    Notes
    -----
    Zone row 0 is the top row (largest ``up``), column 0 the left column
    (smallest ``right``), as seen from the sensor looking out.
    """

    position: np.ndarray
    right: np.ndarray
    up: np.ndarray
    forward: np.ndarray

    def __post_init__(self) -> None:
        pos = _vec3("lidar position", self.position)
        fwd = _unit("lidar forward", self.forward)
        up = _vec3("lidar up", self.up)
        up = up - fwd * float(up @ fwd)
        if np.linalg.norm(up) < 1e-9:
            raise UserError("lidar up must not be parallel to the optical axis (forward)")
        up = up / np.linalg.norm(up)
        right = _vec3("lidar right", self.right)
        # right completes the frame; keep the user's handedness choice (sign of right)
        r = np.cross(up, fwd)
        if float(r @ right) < 0:
            r = -r
        for name, v in (("position", pos), ("right", r), ("up", up), ("forward", fwd)):
            object.__setattr__(self, name, _readonly(v))

    @classmethod
    def look_at(cls, position, target, up_hint=(0.0, 0.0, 1.0)) -> "LidarPose":
        """Pose at ``position`` looking at ``target`` with ``up`` near ``up_hint``.

        ``right`` is the viewer's right-hand side, ``forward x up`` in a
        right-handed world.
        """
        p = _vec3("lidar position", position)
        f = _unit("look-at direction", _vec3("target", target) - p)
        u = _vec3("up hint", up_hint)
        u = u - f * float(u @ f)
        if np.linalg.norm(u) < 1e-9:
            raise UserError("up hint is parallel to the viewing direction; give another up_hint")
        u = u / np.linalg.norm(u)
        return cls(position=p, right=np.cross(f, u), up=u, forward=f)

    @classmethod
    def from_opencv(cls, position, rotation_world_to_camera) -> "LidarPose":
        """Pose from an OpenCV camera (x right, y down, z forward) extrinsic.

        Parameters
        ----------
        position : array_like, shape (3,)
            Camera centre in the world, metres.
        rotation_world_to_camera : array_like, shape (3, 3)
            Rows are the camera's x, y, z axes in world coordinates.
        """
        r = np.asarray(rotation_world_to_camera, dtype=np.float64)
        if r.shape != (3, 3) or not np.all(np.isfinite(r)):
            raise UserError("rotation_world_to_camera must be a finite 3x3 matrix")
        return cls(position=position, right=r[0], up=-r[1], forward=r[2])

    @property
    def basis(self) -> np.ndarray:
        """World-from-sensor matrix, shape (3, 3): columns right, up, forward."""
        return np.stack([self.right, self.up, self.forward], axis=1)

    def directions_to_world(self, dirs: np.ndarray) -> np.ndarray:
        """Sensor-frame directions (..., 3) to world directions (..., 3)."""
        return np.asarray(dirs, dtype=np.float64) @ self.basis.T

    def points_to_sensor(self, points: np.ndarray) -> np.ndarray:
        """World points (..., 3) to sensor-frame coordinates (..., 3), metres."""
        return (np.asarray(points, dtype=np.float64) - self.position) @ self.basis


# --------------------------------------------------------------- rectangles
@dataclass(frozen=True, eq=False)
class Rect:
    """A one-sided Lambertian rectangle (relay wall, table, floor).

    Parameters
    ----------
    center : array_like, shape (3,)
        Centre, metres.
    u_axis, v_axis : array_like, shape (3,)
        In-plane directions of the two sides (made orthonormal, ``u`` kept).
    half_u, half_v : float
        Half side lengths along ``u_axis`` and ``v_axis``, metres (> 0).
    albedo : float
        Lambertian albedo in [0, 1].
    name : str
        Label in reports.

    Notes
    -----
    The lit side is the one ``normal = u_axis x v_axis`` points to; scenes
    check that the LiDAR is on that side.
    """

    center: np.ndarray
    u_axis: np.ndarray
    v_axis: np.ndarray
    half_u: float
    half_v: float
    albedo: float = 0.8
    name: str = "rect"

    def __post_init__(self) -> None:
        c = _vec3(f"{self.name} center", self.center)
        u = _unit(f"{self.name} u_axis", self.u_axis)
        v = _vec3(f"{self.name} v_axis", self.v_axis)
        v = v - u * float(v @ u)
        if np.linalg.norm(v) < 1e-9:
            raise UserError(f"{self.name}: u_axis and v_axis must not be parallel")
        v = v / np.linalg.norm(v)
        for nm in ("half_u", "half_v"):
            val = getattr(self, nm)
            if isinstance(val, bool) or not isinstance(val, (int, float, np.integer, np.floating)) or not (
                math.isfinite(val) and val > 0
            ):
                raise UserError(f"{self.name} {nm}={val!r} must be a finite length > 0 (metres)")
            object.__setattr__(self, nm, float(val))
        if not (isinstance(self.albedo, (int, float, np.integer, np.floating)) and 0 <= float(self.albedo) <= 1):
            raise UserError(f"{self.name} albedo={self.albedo!r} is out of range; allowed: 0 to 1")
        object.__setattr__(self, "albedo", float(self.albedo))
        for nm, val in (("center", c), ("u_axis", u), ("v_axis", v)):
            object.__setattr__(self, nm, _readonly(val))

    @classmethod
    def facing(cls, center, normal, up_hint=(0.0, 0.0, 1.0), *, width: float, height: float,
               albedo: float = 0.8, name: str = "rect") -> "Rect":
        """Rectangle of ``width`` x ``height`` whose lit side faces ``normal``.

        ``height`` runs along ``up_hint`` projected into the plane (for a
        horizontal plane give a horizontal ``up_hint``).
        """
        n = _unit(f"{name} normal", normal)
        h = _vec3("up hint", up_hint)
        h = h - n * float(h @ n)
        if np.linalg.norm(h) < 1e-9:
            raise UserError(f"{name}: up_hint is parallel to the normal; give another up_hint")
        v = h / np.linalg.norm(h)
        u = np.cross(v, n)  # so that u x v = n
        return cls(center=center, u_axis=u, v_axis=v, half_u=width / 2, half_v=height / 2, albedo=albedo, name=name)

    @property
    def normal(self) -> np.ndarray:
        """Unit normal of the lit side, ``u_axis x v_axis``, shape (3,)."""
        u, v = self.u_axis, self.v_axis  # written out: np.cross of two 3-vectors costs ~15 us, called per scene
        return np.array([u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]])

    @property
    def area(self) -> float:
        """Area, m^2."""
        return 4.0 * self.half_u * self.half_v

    def corners(self) -> np.ndarray:
        """Corners, shape (4, 3), counter-clockwise seen from the lit side."""
        c, u, v = self.center, self.u_axis * self.half_u, self.v_axis * self.half_v
        return np.stack([c - u - v, c + u - v, c + u + v, c - u + v])

    def signed_distance(self, points: np.ndarray) -> np.ndarray:
        """Distance of points (..., 3) from the plane, positive on the lit side."""
        return (np.asarray(points, dtype=np.float64) - self.center) @ self.normal

    def local(self, points: np.ndarray) -> np.ndarray:
        """In-plane coordinates (..., 2) of points, metres from the centre."""
        d = np.asarray(points, dtype=np.float64) - self.center
        return np.stack([d @ self.u_axis, d @ self.v_axis], axis=-1)

    def contains(self, points: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether the projections of points (..., 3) fall inside the rectangle."""
        loc = self.local(points)
        return (np.abs(loc[..., 0]) <= self.half_u + margin) & (np.abs(loc[..., 1]) <= self.half_v + margin)


# ---------------------------------------------------------------------- mesh
@dataclass(frozen=True, eq=False)
class Mesh:
    """A triangle mesh in its own frame (metres).

    Parameters
    ----------
    vertices : array_like, shape (V, 3)
    faces : array_like of int, shape (F, 3)
        Counter-clockwise seen from outside (normals point out).
    name : str

    Raises
    ------
    UserError
        Empty mesh, non-finite vertices, or face indices out of range.
    """

    vertices: np.ndarray
    faces: np.ndarray
    name: str = "mesh"

    def __post_init__(self) -> None:
        try:
            v = np.asarray(self.vertices, dtype=np.float64)
            f = np.asarray(self.faces)
        except (TypeError, ValueError):
            raise UserError(f"mesh {self.name!r}: vertices and faces must be numeric arrays") from None
        if v.ndim != 2 or v.shape[1] != 3 or v.shape[0] == 0:
            raise UserError(f"mesh {self.name!r} has no vertices (need an array of shape (V, 3))")
        if f.ndim != 2 or f.shape[1] != 3 or f.shape[0] == 0:
            raise UserError(f"mesh {self.name!r} has no triangles (need faces of shape (F, 3))")
        if not np.issubdtype(f.dtype, np.integer):
            raise UserError(f"mesh {self.name!r}: face indices must be integers")
        bad = ~np.all(np.isfinite(v), axis=1)
        if np.any(bad):
            i = int(np.argmax(bad))
            raise UserError(f"mesh {self.name!r}: vertex {i} is {v[i].tolist()}; all vertices must be finite")
        if f.min() < 0 or f.max() >= v.shape[0]:
            raise UserError(f"mesh {self.name!r}: face index out of range 0..{v.shape[0] - 1}")
        object.__setattr__(self, "vertices", _readonly(v))
        object.__setattr__(self, "faces", _readonly(f.astype(np.int64)))

    # the mesh is immutable (read-only arrays): derived arrays are computed once, read-only too
    @functools.cached_property
    def triangles(self) -> np.ndarray:
        """Vertex positions per face, shape (F, 3, 3)."""
        return _readonly(self.vertices[self.faces])

    @functools.cached_property
    def face_areas(self) -> np.ndarray:
        """Area of each face, shape (F,), m^2 (0 for degenerate faces)."""
        t = self.triangles
        return _readonly(0.5 * np.linalg.norm(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]), axis=1))

    @functools.cached_property
    def face_normals(self) -> np.ndarray:
        """Unit outward normal of each face, shape (F, 3); zero for degenerate faces."""
        t = self.triangles
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        return _readonly(np.where(norm > 0, n / np.where(norm > 0, norm, 1.0), 0.0))

    @functools.cached_property
    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        """Centre (3,) in the mesh frame and radius (m) of a sphere holding every vertex (the bounding box's
        centre; not the smallest such sphere)."""
        c = (self.vertices.min(axis=0) + self.vertices.max(axis=0)) / 2
        return _readonly(c), float(np.linalg.norm(self.vertices - c, axis=1).max())

    @functools.cached_property
    def content_key(self) -> str:
        """A digest of the vertices and faces (what derived data such as a surface quadrature is cached by)."""
        return hashlib.sha1(self.vertices.tobytes() + b"|" + self.faces.tobytes()).hexdigest()

    @property
    def area(self) -> float:
        """Total surface area, m^2."""
        return float(self.face_areas.sum())


def rigid_transform(rotation=None, translation=(0.0, 0.0, 0.0)) -> np.ndarray:
    """4x4 homogeneous transform from a 3x3 rotation and a translation (metres)."""
    m = np.eye(4)
    if rotation is not None:
        m[:3, :3] = np.asarray(rotation, dtype=np.float64)
    m[:3, 3] = _vec3("translation", translation)
    return m


_EYE3 = np.eye(3)
_LAST_ROW = np.array([0.0, 0.0, 0.0, 1.0])


def _check_transform(name: str, m: Any) -> np.ndarray:
    try:
        m = np.asarray(m, dtype=np.float64)
    except (TypeError, ValueError):
        raise UserError(f"{name} to_world must be a 4x4 matrix") from None
    if m.shape != (4, 4) or not np.all(np.isfinite(m)):
        raise UserError(f"{name} to_world must be a finite 4x4 matrix")
    r = m[:3, :3]
    # np.allclose's tests written out (it costs ~20 us a call; datasets build thousands of poses)
    orthonormal = (np.abs(r.T @ r - _EYE3) <= 1e-3 + 1e-5 * _EYE3).all()
    affine = (np.abs(m[3] - _LAST_ROW) <= 1e-8 + 1e-5 * _LAST_ROW).all()
    if not orthonormal or not affine:
        raise UserError(f"{name} to_world must be a rigid transform (rotation + translation)")
    return m


@dataclass(frozen=True, eq=False)
class HiddenObject:
    """A hidden object: mesh, pose and reflectance.

    Parameters
    ----------
    mesh : Mesh
        Geometry in the object frame.
    to_world : array_like, shape (4, 4)
        Rigid object-to-world transform.
    reflectance : {"retroreflective", "lambertian"}
        Retroreflective: light returns towards where it came from in a
        Gaussian lobe of FWHM ``lobe_fwhm_deg`` (plus the Lambertian base
        ``diffuse_albedo``). Lambertian: diffuse.
    albedo : float
        Fraction of the incident power reflected, in [0, 1]: by the lobe
        (retroreflective) or diffusely (Lambertian).
    lobe_fwhm_deg : float
        Angular FWHM of the retroreflected lobe, degrees (>= 0; retroreflective only).
    diffuse_albedo : float
        Retroreflective objects only: the fraction of the incident power
        reflected diffusely (a Lambertian base under the retroreflective
        tape, bare edges), in [0, 1] with ``albedo + diffuse_albedo <= 1``.
        0 (default) is a pure retroreflector.
    fixture : bool
        Part of the rig that moves with the gantry (the object's mount):
        it stays in the background capture, see :meth:`Scene.without_objects`.
    name : str
    support : bool
        Part of the rig that holds the hidden object (DENALI's mount and its
        plate): a smooth, secondary addition to the object's signal, so the
        fast simulator samples its surface with the fidelity's
        ``support_samples`` instead of ``object_samples`` and lights it
        through ``support_flash_sub`` wall cells per zone axis instead of
        ``flash_sub`` (:class:`~nlosplan.simulators.fast.fidelity.Fidelity`).

    Notes
    -----
    The two parts of a retroreflective object add: radiance leaving a
    surface point lit with irradiance ``E`` from direction ``w_l`` is
    ``albedo p(w) E / cos(w) + diffuse_albedo E / pi`` with ``p`` the lobe
    (a unit-mass density over directions around ``w_l``).
    """

    mesh: Mesh
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))
    reflectance: str = "retroreflective"
    albedo: float = 0.5
    lobe_fwhm_deg: float = 2.0
    name: str = "object"
    diffuse_albedo: float = 0.0
    fixture: bool = False
    support: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.mesh, Mesh):
            raise UserError(f"object {self.name!r}: mesh must be a Mesh")
        object.__setattr__(self, "to_world", _readonly(_check_transform(f"object {self.name!r}", self.to_world)))
        if self.reflectance not in REFLECTANCES:
            raise UserError(f"reflectance={self.reflectance!r} is unknown; allowed: {', '.join(REFLECTANCES)}")
        if not (isinstance(self.albedo, (int, float, np.integer, np.floating)) and 0 <= float(self.albedo) <= 1):
            raise UserError(f"object albedo={self.albedo!r} is out of range; allowed: 0 to 1")
        lobe = self.lobe_fwhm_deg
        if not (isinstance(lobe, (int, float, np.integer, np.floating)) and math.isfinite(lobe) and 0 <= lobe <= 90):
            raise UserError(f"lobe_fwhm_deg={lobe!r} is out of range; allowed: 0 to 90 degrees")
        diff = self.diffuse_albedo
        if isinstance(diff, bool) or not (isinstance(diff, (int, float, np.integer, np.floating)) and 0 <= float(diff) <= 1):
            raise UserError(f"object diffuse_albedo={diff!r} is out of range; allowed: 0 to 1")
        if float(diff) > 0 and self.reflectance == "lambertian":
            raise UserError(f"object {self.name!r}: diffuse_albedo is the Lambertian base of a retroreflective object; "
                            "a Lambertian object's diffuse albedo is its albedo")
        if float(self.albedo) + float(diff) > 1 + 1e-12:
            raise UserError(f"object {self.name!r}: albedo {float(self.albedo):g} + diffuse_albedo {float(diff):g} "
                            "reflects more than the incident power; their sum must be <= 1")
        if not isinstance(self.fixture, (bool, np.bool_)):
            raise UserError(f"fixture={self.fixture!r} must be true or false")
        if not isinstance(self.support, (bool, np.bool_)):
            raise UserError(f"support={self.support!r} must be true or false")
        object.__setattr__(self, "albedo", float(self.albedo))
        object.__setattr__(self, "lobe_fwhm_deg", float(lobe))
        object.__setattr__(self, "diffuse_albedo", float(diff))
        object.__setattr__(self, "fixture", bool(self.fixture))
        object.__setattr__(self, "support", bool(self.support))

    def world_vertices(self) -> np.ndarray:
        """Mesh vertices in the world frame, shape (V, 3)."""
        return self.mesh.vertices @ self.to_world[:3, :3].T + self.to_world[:3, 3]

    def bounding_sphere(self) -> tuple[np.ndarray, float]:
        """World centre (3,) and radius (m) of a sphere holding the posed mesh (:attr:`Mesh.bounding_sphere`)."""
        centre, radius = self.mesh.bounding_sphere
        return self.to_world[:3, :3] @ centre + self.to_world[:3, 3], radius

    def moved_to(self, to_world) -> "HiddenObject":
        """Copy at another pose."""
        return dataclasses.replace(self, to_world=to_world)


# --------------------------------------------------------------------- scene
@dataclass(frozen=True, eq=False)
class Scene:
    """An NLOS scene: a flash LiDAR facing a relay wall, hidden objects beside it.

    Parameters
    ----------
    lidar : LidarPose
    wall : Rect
        The relay wall (the only relay surface of three-bounce paths).
    planes : tuple of Rect
        Other visible planes (tables, floor): they add first-bounce returns.
    objects : tuple of HiddenObject
        Hidden geometry; an empty tuple is the background (no object) scene.
    lights_on : bool
        Room lights on (the sensor's ambient rate applies) or off.
    name : str
    meta : mapping
        Labels carried into datasets (object, size, position index, ...).

    Raises
    ------
    UserError
        The LiDAR behind the wall, or an object intersecting the wall or
        lying behind it.
    """

    lidar: LidarPose
    wall: Rect
    planes: tuple = ()
    objects: tuple = ()
    lights_on: bool = False
    name: str = "scene"
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.lidar, LidarPose):
            raise UserError("scene lidar must be a LidarPose")
        if not isinstance(self.wall, Rect):
            raise UserError("scene wall must be a Rect")
        object.__setattr__(self, "planes", tuple(self.planes))
        object.__setattr__(self, "objects", tuple(self.objects))
        object.__setattr__(self, "meta", dict(self.meta))
        if not isinstance(self.lights_on, (bool, np.bool_)):
            raise UserError(f"lights_on={self.lights_on!r} must be true or false")
        object.__setattr__(self, "lights_on", bool(self.lights_on))
        if float(self.wall.signed_distance(self.lidar.position)) <= 0:
            raise UserError("the LiDAR is behind the relay wall (it must be on the side the wall's normal points to)")
        for p in self.planes:
            if not isinstance(p, Rect):
                raise UserError("scene planes must be Rect objects")
        for obj in self.objects:
            if not isinstance(obj, HiddenObject):
                raise UserError("scene objects must be HiddenObject instances")
            _check_object_vs_wall(obj, self.wall)

    def without_objects(self, keep_fixtures: bool = True) -> "Scene":
        """The background scene: same rig, the hidden objects taken away.

        Parameters
        ----------
        keep_fixtures : bool
            Keep the objects marked ``fixture`` (the mount that stays on the
            gantry), as in DENALI's NOOBJECT capture; False removes them too
            (NOOBJECTMOUNT: no object mount).
        """
        kept = tuple(o for o in self.objects if o.fixture) if keep_fixtures else ()
        return dataclasses.replace(self, objects=kept, meta={**self.meta, "background": True})

    def replace(self, **changes: Any) -> "Scene":
        """Copy with fields changed (validated again)."""
        return dataclasses.replace(self, **changes)


def _check_object_vs_wall(obj: HiddenObject, wall: Rect) -> None:
    centre, radius = obj.bounding_sphere()
    if float(wall.signed_distance(centre)) > radius:
        return  # wholly on the lit side: neither behind the wall nor through it (every DENALI scene's objects)
    v = obj.world_vertices()
    s = wall.signed_distance(v)
    if float(s.max()) <= 0:
        raise UserError(
            f"object {obj.name!r} lies behind the relay wall (all of it is on the far side of the wall's plane)"
        )
    behind = s <= 0
    if np.any(behind & wall.contains(v)):
        depth = float(-s[behind].min()) * 1000
        raise UserError(
            f"object {obj.name!r} intersects the relay wall ({depth:.1f} mm through it); move it in front of the wall"
        )
    # triangles that cross the plane inside the rectangle also intersect it
    tri_s = s[obj.mesh.faces]
    crossing = (tri_s.min(axis=1) < 0) & (tri_s.max(axis=1) > 0)
    if np.any(crossing):
        tv = v[obj.mesh.faces[crossing]]
        ts = tri_s[crossing]
        for a, b in ((0, 1), (1, 2), (2, 0)):
            sa, sb = ts[:, a], ts[:, b]
            cut = (sa * sb) < 0
            if not np.any(cut):
                continue
            t = sa[cut] / (sa[cut] - sb[cut])
            p = tv[cut, a] + t[:, None] * (tv[cut, b] - tv[cut, a])
            if np.any(wall.contains(p)):
                raise UserError(f"object {obj.name!r} intersects the relay wall; move it in front of the wall")


def warn(message: str) -> None:
    """Issue an :class:`NLOSWarning` (the CLI prints it as one ``warning:`` line)."""
    warnings.warn(message, NLOSWarning, stacklevel=3)
