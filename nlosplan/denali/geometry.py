"""The DENALI gantry in millimetres: grid, snake order, and the object pose at any (x, y).

Gantry frame
------------
DENALI scans a 10 x 10 snake raster over 0-320 mm per axis (pitch 320/9 ≈
35.56 mm, SENSOR_FACTS.md), in the order of its capture code: cc-hardware's
``SnakeStepperController`` with the axes ``x`` then ``y``
(``capture/capture_spad_nlos.py``) steps ``x`` slowly and runs ``y`` back
and forth, and its gantry drives ``x`` with the motor on CNC-shield pins 2/5
(``SingleDrive1AxisGantryXConfig``). Position index ``p`` -- DENALI's capture
``p``, the index of its published poses (``poses.json``, ``tag1_positions``)
-- is column ``c = p // 10`` of gantry ``x`` and step ``k = p % 10`` along
gantry ``y``; even columns run up ``y`` and odd ones back, so the gantry row
is ``k`` on even columns and ``9 - k`` on odd ones:

    x_mm = (p // 10) * pitch,   y_mm = (k if (p // 10) % 2 == 0 else 9 - k) * pitch.

Positions 0 and 1 differ in ``y`` only; 9 and 10 in ``x`` only.

Object pose at an arbitrary position
------------------------------------
DENALI published the object's pose only at the 100 grid points. Between them
the pose is interpolated: the translation is an affine fit to all 100 tag
poses plus the bilinearly interpolated residual of that fit (so it is exact
at the grid points and continuous between them; outside the grid the
residual is held at the nearest edge), and the rotation is the bilinear
blend of the four neighbouring rotations projected back onto a rotation
(SVD). The localization label (DENALI's ``tag1_positions``) is interpolated
the same way.
"""

from __future__ import annotations

import math
from functools import lru_cache

import numpy as np

from nlosplan.denali.rig import object_poses, tag1_positions
from nlosplan.errors import UserError

__all__ = ["GRID_N", "PITCH_MM", "TRAVEL_MM", "grid_index", "grid_mm", "label_xy", "object_pose_mm"]

GRID_N = 10
TRAVEL_MM = 320.0
PITCH_MM = TRAVEL_MM / (GRID_N - 1)
_TOL_MM = 0.05


def grid_mm(position: int) -> tuple[float, float]:
    """Gantry (x, y) in mm of DENALI grid position ``position`` (0-99: DENALI's capture order, x slow, y snaking)."""
    p = int(position)
    if not 0 <= p < GRID_N * GRID_N:
        raise UserError(f"grid position {position!r} is out of range; allowed: 0 to {GRID_N * GRID_N - 1}")
    col, k = divmod(p, GRID_N)
    row = k if col % 2 == 0 else GRID_N - 1 - k
    return col * PITCH_MM, row * PITCH_MM


def grid_index(x_mm: float, y_mm: float) -> int:
    """The DENALI position index at (x, y) mm (within 0.05 mm), else -1."""
    col, row = x_mm / PITCH_MM, y_mm / PITCH_MM
    c, r = round(col), round(row)
    if not (0 <= c < GRID_N and 0 <= r < GRID_N):
        return -1
    if abs(col - c) * PITCH_MM > _TOL_MM or abs(row - r) * PITCH_MM > _TOL_MM:
        return -1
    return c * GRID_N + (r if c % 2 == 0 else GRID_N - 1 - r)


@lru_cache(maxsize=1)
def _tables():
    poses = np.asarray(object_poses())
    labels = np.asarray(tag1_positions())[:, :2]
    grid = np.zeros((GRID_N, GRID_N, 4, 4))
    lab = np.zeros((GRID_N, GRID_N, 2))
    xy = np.zeros((GRID_N * GRID_N, 2))
    for p in range(GRID_N * GRID_N):
        x, y = grid_mm(p)
        r, c = round(y / PITCH_MM), round(x / PITCH_MM)
        grid[r, c], lab[r, c], xy[p] = poses[p], labels[p], (x, y)
    design = np.column_stack([xy, np.ones(len(xy))])  # (100, 3)
    a_t, *_ = np.linalg.lstsq(design, poses[:, :3, 3], rcond=None)   # (3, 3)
    a_l, *_ = np.linalg.lstsq(design, labels, rcond=None)             # (3, 2)
    rows, cols = np.meshgrid(np.arange(GRID_N), np.arange(GRID_N), indexing="ij")
    g = np.column_stack([cols.ravel() * PITCH_MM, rows.ravel() * PITCH_MM, np.ones(rows.size)])
    res_t = grid[..., :3, 3] - (g @ a_t).reshape(GRID_N, GRID_N, 3)
    res_l = lab - (g @ a_l).reshape(GRID_N, GRID_N, 2)
    return grid[..., :3, :3], a_t, res_t, a_l, res_l


def _bilinear(table: np.ndarray, x_mm: float, y_mm: float) -> np.ndarray:
    u = min(max(x_mm / PITCH_MM, 0.0), GRID_N - 1.0)
    v = min(max(y_mm / PITCH_MM, 0.0), GRID_N - 1.0)
    c0, r0 = min(int(u), GRID_N - 2), min(int(v), GRID_N - 2)
    fu, fv = u - c0, v - r0
    return ((1 - fu) * (1 - fv) * table[r0, c0] + fu * (1 - fv) * table[r0, c0 + 1]
            + (1 - fu) * fv * table[r0 + 1, c0] + fu * fv * table[r0 + 1, c0 + 1])


def _check_mm(x_mm: float, y_mm: float) -> tuple[float, float]:
    x, y = float(x_mm), float(y_mm)
    if not (math.isfinite(x) and math.isfinite(y)):
        raise UserError(f"gantry position ({x_mm!r}, {y_mm!r}) mm is not finite")
    return x, y


def object_pose_mm(x_mm: float, y_mm: float) -> np.ndarray:
    """Object-to-world transform, shape (4, 4), metres, with the gantry at (x, y) mm.

    Equals :func:`nlosplan.denali.rig.object_pose` at the grid
    points (see the module notes for the interpolation between them).
    """
    x, y = _check_mm(x_mm, y_mm)
    rot, a_t, res_t, _, _ = _tables()
    blend = _bilinear(rot, x, y)
    u, _, vt = np.linalg.svd(blend)
    r = u @ vt
    if np.linalg.det(r) < 0:
        u[:, -1] *= -1
        r = u @ vt
    out = np.eye(4)
    out[:3, :3] = r
    out[:3, 3] = np.array([x, y, 1.0]) @ a_t + _bilinear(res_t, x, y)
    return out


def label_xy(x_mm: float, y_mm: float) -> tuple[float, float]:
    """DENALI's localization label (world x, y in metres) with the gantry at (x, y) mm."""
    x, y = _check_mm(x_mm, y_mm)
    _, _, _, a_l, res_l = _tables()
    v = np.array([x, y, 1.0]) @ a_l + _bilinear(res_l, x, y)
    return float(v[0]), float(v[1])

