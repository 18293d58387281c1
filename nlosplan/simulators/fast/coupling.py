"""Geometric coupling between a point on the object and a cell of the wall.

For an object point ``x`` (unit normal ``n_x``) and a wall cell ``P`` (lit
normal ``n_w``) the coupling is

    C(x, P) = integral over P of  max(cos_w, 0) * max(cos_x, 0) / d^2  dA

(m^0: a solid-angle-like quantity; ``pi * C`` is ``pi`` times the form
factor from ``x`` to ``P``). Irradiance at ``x`` from a wall cell of
radiance ``L`` is ``L * C``; by reciprocity the same ``C`` carries light
from ``x`` back to the cell.

Far from the cell the midpoint rule ``cos_w cos_x A / d^2`` is accurate to
``O((size / d)^2)``. Close to the wall it is not: at 1 mm from the wall a
point sample of ``1/d^4`` would be ``A / h^2``, unbounded, while the true
integral is at most ``pi``. :func:`polygon_coupling` integrates exactly with
Lambert's contour formula over the cell polygon clipped to the hemisphere
``n_x . (p - x) >= 0``.
"""

from __future__ import annotations

import math

from nlosplan._jax import jnp

_TINY = 1e-30
#: Cephes' single-precision arctangent on [0, tan(pi/8)] (odd polynomial in t, coefficients of t^3 ... t^9), and the
#: reduction bound tan(pi/8).
_ATAN_POLY = (-3.33329491539e-1, 1.99777106478e-1, -1.38776856032e-1, 8.05374449538e-2)
_TAN_PI_8 = 0.41421356237309503


def far_coupling(cells_t, area, x, n_x, height):
    """Midpoint-rule coupling between object points and wall cells (structure of arrays).

    Parameters
    ----------
    cells_t : array, shape (3, N)
        Cell centres (on the wall plane), metres, transposed.
    area : array, shape (N,)
        Cell areas, m^2.
    x : array, shape (M, 3)
        Object points, metres.
    n_x : array, shape (M, 3)
        Their unit normals.
    height : array, shape (M,)
        Distance of each point in front of the wall plane, metres
        (``cos_w * d``, the same for every cell of the plane).

    Returns
    -------
    coupling : array, shape (M, N)
        ``max(h, 0) * max(d . n_x, 0) * area / |d|^4`` with ``d`` = cell - point.
    dist : array, shape (M, N)
        ``|d|``, metres.

    Notes
    -----
    Written component by component: on CPUs this vectorises about ten times
    better than arrays with a trailing axis of 3.
    """
    dx = cells_t[0][None, :] - x[:, 0, None]
    dy = cells_t[1][None, :] - x[:, 1, None]
    dz = cells_t[2][None, :] - x[:, 2, None]
    d2 = jnp.maximum(dx * dx + dy * dy + dz * dz, _TINY)
    cx = jnp.maximum(dx * n_x[:, 0, None] + dy * n_x[:, 1, None] + dz * n_x[:, 2, None], 0.0)
    inv = 1.0 / d2
    return jnp.maximum(height, 0.0)[:, None] * cx * area[None, :] * inv * inv, jnp.sqrt(d2)


def _cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def _dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def _angle(y, x):
    """``atan2(y, x)`` for ``y >= 0`` (in [0, pi]), elementwise.

    XLA's CPU backend computes ``atan2`` one element at a time (~20 ns each, most of the exact near-wall coupling's
    cost); in float32 this is Cephes' ``atanf`` (range reduction to ``[0, tan(pi/8)]``, an odd polynomial: within
    3e-7 of the exact angle, float32's own rounding, and ~2.5 ns) in plain arithmetic that vectorises. Other dtypes
    (the float64 references, derivative tests) keep ``jnp.arctan2``.

    Parameters
    ----------
    y : array, shape (...)
        The sine side, >= 0 (here ``|a x b|``).
    x : array, shape (...)
        The cosine side (here ``a . b``).

    Returns
    -------
    array, shape (...)
        The angle, radians.
    """
    if y.dtype != jnp.float32:
        return jnp.arctan2(y, x)
    ax = jnp.abs(x)
    big = y > ax
    lo, hi = jnp.where(big, ax, y), jnp.where(big, y, ax)
    r = lo / jnp.maximum(hi, _TINY)  # in [0, 1]
    mid = r > _TAN_PI_8
    t = jnp.where(mid, (r - 1.0) / (r + 1.0), r)  # in [-tan(pi/8), tan(pi/8)]
    z = t * t
    p = _ATAN_POLY[3]
    for c in _ATAN_POLY[2::-1]:
        p = p * z + c
    a = jnp.where(mid, math.pi / 4, 0.0) + t + t * z * p  # atan(lo / hi) in [0, pi/4]
    a = jnp.where(big, math.pi / 2 - a, a)  # atan(y / |x|)
    return jnp.where(x < 0, math.pi - a, a)


def _edge_term(a, b, n):
    """Lambert edge term ``angle(a, b) * n . (a x b) / |a x b|`` (0 for degenerate edges).

    Vectors are tuples of three arrays (structure of arrays).
    """
    c = _cross(a, b)
    c2 = _dot(c, c)
    ok = c2 > _TINY
    norm = jnp.sqrt(jnp.where(ok, c2, 1.0))
    angle = _angle(norm, _dot(a, b))
    return jnp.where(ok, angle * _dot(n, c) / norm, 0.0)


def polygon_coupling(x, n_x, corners):
    """Exact coupling of points to convex planar polygons, hemisphere-clipped.

    Parameters
    ----------
    x : array, shape (M, 3)
        Object points, metres.
    n_x : array, shape (M, 3)
        Their unit normals.
    corners : array, shape (K, V, 3)
        Polygon vertices, counter-clockwise seen from the points' side.

    Returns
    -------
    array, shape (M, K)
        ``integral of cos_w cos_x / d^2 dA`` over the part of each polygon
        in front of each point (>= 0, at most ``pi``).

    Notes
    -----
    Lambert: ``integral = 1/2 * sum_edges angle_i * n_x . g_i`` with ``g_i``
    the unit normal of the plane through ``x`` and edge ``i``. Clipping a
    convex polygon by the plane ``n_x . (p - x) = 0`` shortens the edges that
    cross it and adds one closing edge from the exit to the entry point.
    Computed component-wise on (M, K) arrays.
    """
    n = tuple(n_x[:, a, None] for a in range(3))
    verts = [tuple(corners[None, :, v, a] - x[:, a, None] for a in range(3)) for v in range(corners.shape[1])]
    heights = [_dot(r, n) for r in verts]
    zero = jnp.zeros_like(heights[0])
    total = zero
    p_exit = (zero, zero, zero)
    p_entry = (zero, zero, zero)
    clipped = jnp.zeros(zero.shape, bool)
    nv = len(verts)
    for i in range(nv):
        a, b = verts[i], verts[(i + 1) % nv]
        sa, sb = heights[i], heights[(i + 1) % nv]
        ina, inb = sa >= 0, sb >= 0
        cross = ina != inb
        t = jnp.where(cross, sa / jnp.where(cross, sa - sb, 1.0), 0.0)
        p = tuple(a[k] + t * (b[k] - a[k]) for k in range(3))
        start = tuple(jnp.where(ina, a[k], p[k]) for k in range(3))
        end = tuple(jnp.where(inb, b[k], p[k]) for k in range(3))
        total = total + jnp.where(ina | inb, _edge_term(start, end, n), 0.0)
        is_exit, is_entry = ina & ~inb, ~ina & inb
        p_exit = tuple(jnp.where(is_exit, p[k], p_exit[k]) for k in range(3))
        p_entry = tuple(jnp.where(is_entry, p[k], p_entry[k]) for k in range(3))
        clipped = clipped | is_exit
    total = total + jnp.where(clipped, _edge_term(p_exit, p_entry, n), 0.0)
    # counter-clockwise loops give negative terms
    return jnp.maximum(-0.5 * total, 0.0)
