"""The DENALI capture rig (CVPR 2026) as data: objects, sizes, class groups, poses, labels, placement.

Sources
-------
Geometry, calibration and meshes are the public DENALI repository's
(github.com/NikhilBehari/denali, commit 9e1083293a4f6aac5e674c9bf0d948dc0697f8c3,
MIT licence), packaged in ``nlosplan/denali/data``. Placement follows
DENALI's own digital twin (``digitaltwin/scene.py``):

- LiDAR: the co-located camera of ``cameras.json`` (OpenCV extrinsic); the
  TMF8828 sits rigidly on the same mount and looks the same way
  (:func:`camera_pose`).
- Relay wall: a :data:`WALL_SIZE` rectangle placed from wall tag 5
  (:data:`WALL_TAG_MARGIN`, :data:`WALL_TAG_DROP`).
- Tables: two :data:`TABLE_SIZE` rectangles placed from tags 14 and 15.
- Object at gantry position ``p``: ``T(tag 1 at p) . Rx(-90 deg) .
  translate(0, -0.005, -0.04)`` (the mount's y-up to z-up turn and offset,
  :data:`MOUNT_OFFSET`), with tag 1's averaged pose from ``poses.json``
  (:func:`object_poses`). The mesh's -z face then looks at the wall from
  about 0.3 m.

World frame: the tracking rig's, metres, z up; tables at z ~ 0, relay wall
near y ~ 0.80, LiDAR at (0.459, 0.321, 0.373).

Localization labels
-------------------
:func:`positions_xy` returns DENALI's localization labels
(``tag1_positions.json``, what its benchmark regresses). They sit a nearly
constant (0.038, 0.028) m (in x, y) from the averaged tag-1 poses that place
the mesh; both are kept as published.

This module knows no light transport and no scene types: the simulators
room builds a :class:`~nlosplan.simulators.scene.Scene` from these facts
(:func:`nlosplan.simulators.presets.denali.denali_scene`).
"""

from __future__ import annotations

import json
import math
from functools import lru_cache
from importlib import resources
from importlib.resources.abc import Traversable
from typing import Any

import numpy as np

from nlosplan.errors import UserError

__all__ = [
    "ALIASES", "CLASS_GROUPS", "DENALI_OBJECTS", "MOUNT_OFFSET", "N_POSITIONS", "SIZES", "TABLE_SIZE",
    "plate_pose",
    "WALL_SIZE", "WALL_TAG_DROP", "WALL_TAG_MARGIN", "camera_pose", "check_object", "check_position", "check_size",
    "class_group", "data_dir", "object_pose", "object_poses", "positions_xy", "read_json", "tag1_positions",
    "tag_pose", "tag_transform",
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

#: Other spellings of object names accepted on input (DENALI's file names write ``i`` for ``I``).
ALIASES = {"i": "I"}
WALL_SIZE = (0.93, 0.6096)  # along tag-5 x, along tag-5 y (metres)
TABLE_SIZE = (0.78, 1.524)  # along tag x, along tag y (metres)
WALL_TAG_MARGIN = 0.068 / 2  # half the wall tags' printed size (metres)
WALL_TAG_DROP = 0.186  # tag 5 above the wall's bottom edge (metres)
MOUNT_OFFSET = (0.0, -0.005, -0.04)  # object/mount frame offset from tag 1 (metres)


def data_dir() -> Traversable:
    """The packaged DENALI files (``cameras.json``, ``poses.json``, ``tag1_positions.json``, meshes)."""
    return resources.files("nlosplan.denali") / "data"


@lru_cache(maxsize=None)
def read_json(name: str) -> dict:
    """A packaged DENALI JSON file, parsed (cached; do not modify it)."""
    return json.loads((data_dir() / name).read_text(encoding="utf-8"))


def tag_transform(pose: dict) -> np.ndarray:
    """4x4 world-from-tag transform of a ``poses.json`` entry (``rotation_matrix``, ``center``), metres."""
    m = np.eye(4)
    m[:3, :3] = np.asarray(pose["rotation_matrix"], dtype=np.float64)
    m[:3, 3] = np.asarray(pose["center"], dtype=np.float64).reshape(3)
    return m


def tag_pose(tag_id: str) -> np.ndarray:
    """World-from-tag transform, shape (4, 4), of a fixed rig tag (``"5"``: relay wall, ``"14"``/``"15"``: tables)."""
    return tag_transform(read_json("poses.json")["tracking_avgposes"][str(tag_id)])


def camera_pose() -> tuple[np.ndarray, np.ndarray]:
    """The co-located camera (the LiDAR's mount): position (3,) in metres and OpenCV rotation (3, 3)."""
    cam = read_json("cameras.json")["COLOCATED_CAMERA"]
    return np.asarray(cam["position"], dtype=np.float64), np.asarray(cam["rotation_matrix"], dtype=np.float64)


def check_object(obj: Any) -> str:
    """The DENALI object name (``"i"`` becomes ``"I"``); a UserError names the allowed ones."""
    name = ALIASES.get(obj, obj) if isinstance(obj, str) else obj
    if name not in DENALI_OBJECTS:
        raise UserError(f"unknown DENALI object {obj!r}; allowed: {', '.join(DENALI_OBJECTS)} ('i' = 'I')")
    return name


def check_size(size: Any) -> str:
    """A DENALI object size, ``"4in"`` or ``"8in"``; a UserError otherwise."""
    if size not in SIZES:
        raise UserError(f"unknown DENALI object size {size!r}; allowed: {', '.join(SIZES)}")
    return size


def check_position(position: Any) -> int:
    """A DENALI gantry position index, 0 to 99; a UserError otherwise."""
    if isinstance(position, bool) or not isinstance(position, (int, np.integer)) or not 0 <= position < N_POSITIONS:
        raise UserError(f"DENALI position={position!r} is not allowed; allowed: integers 0 to {N_POSITIONS - 1}")
    return int(position)


def class_group(obj: str) -> str:
    """Class group of a DENALI object: ``"numbers"``, ``"letters"`` or ``"shapes"``."""
    name = check_object(obj)
    return next(g for g, names in CLASS_GROUPS.items() if name in names)


@lru_cache(maxsize=None)
def object_poses() -> np.ndarray:
    """Object-to-world transforms at every gantry position, shape (100, 4, 4), metres (read-only).

    ``T(tag 1 at p) . Rx(-90 deg) . translate(MOUNT_OFFSET)``.
    """
    a = -math.pi / 2  # DENALI's y-up to z-up turn about x
    rx = np.eye(4)
    rx[:3, :3] = [[1, 0, 0], [0, math.cos(a), -math.sin(a)], [0, math.sin(a), math.cos(a)]]
    offset = np.eye(4)
    offset[:3, 3] = MOUNT_OFFSET
    poses = read_json("poses.json")["tracking_tag1_index_avgposes"]
    out = np.stack([tag_transform(poses[str(p)]) @ rx @ offset for p in range(N_POSITIONS)])
    out.setflags(write=False)
    return out


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
    return np.array(object_poses()[check_position(position)])


def plate_pose(object_to_world: np.ndarray) -> np.ndarray:
    """Pose of the mount plate (tag 1's frame turned z-up) for an object pose, shape (4, 4), metres.

    ``object_to_world @ translate(-MOUNT_OFFSET)``: what DENALI's twin uses
    for the plate (the object sits ``MOUNT_OFFSET`` from tag 1).
    """
    back = np.eye(4)
    back[:3, 3] = -np.asarray(MOUNT_OFFSET)
    return np.asarray(object_to_world, dtype=np.float64) @ back


@lru_cache(maxsize=None)
def tag1_positions() -> np.ndarray:
    """DENALI's published tag-1 positions (``tag1_positions.json``), shape (100, 3), metres (read-only)."""
    raw = read_json("tag1_positions.json")
    out = np.array([raw[f"frame{p}_tag1"] for p in range(N_POSITIONS)], dtype=np.float64)
    out.setflags(write=False)
    return out


def positions_xy() -> np.ndarray:
    """DENALI's localization labels: world (x, y) of tag 1 per position, shape (100, 2), metres."""
    return np.array(tag1_positions()[:, :2])
