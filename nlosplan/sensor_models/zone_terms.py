"""Per-zone terms of a sensor: gain, time offset (TDC delay), time scale (TDC rate) and near-field overlap.

Every backend applies them the same way, to the light of each zone before
the impulse response: arrivals (``pipeline.expected_histogram``) or node
transients (the fast simulator, the Mitsuba twin, the calibration model)
through :func:`apply_zone_terms`. All functions are pure JAX and
differentiable in the per-zone values.

Notes
-----
Zone ``z`` records light arriving at time ``t`` (from a surface at range
``r = c t / 2`` for a first bounce) at ``s_z t + delta_z`` with weight

    g_z * r^2 / (r^2 + d0_z^2)

``g_z`` the zone's gain (SPAD count, detection efficiency), ``delta_z`` its
time offset, ``s_z`` the rate of its clock (time scale, 1 nominal),
``d0_z`` its near-field overlap distance: the fraction of the
zone's view lit by the flash falls at short range, half at ``r = d0``.
Crosstalk (light that never leaves the sensor, ``t = 0``) takes the gain and
the offset but not the overlap. With a time walk ``w`` (ps per decade) the
zone's light is recorded ``w log10(Lambda_z)`` earlier, ``Lambda_z`` its signal
photons per iteration arriving inside the window (after gain, overlap and the
zone's clock; crosstalk included), held at its values at ``10^-WALK_DECADES`` and
``10^WALK_DECADES`` photons per iteration. The bound makes the largest shift a
property of the sensor (:func:`walk_reach_ps`), so node grids can hold every
arrival the walk can move into the window and every place it can move content
to: a result does not depend on how far a grid reaches beyond that.
"""

from __future__ import annotations

import numpy as np

from nlosplan._jax import jnp
from nlosplan.constants import C_M_PER_PS
from nlosplan.sensor_models.config import SensorConfig

#: The time walk follows ``log10`` of a zone's light over this many decades either side of 1 photon per iteration.
WALK_DECADES = 6.0


def zone_values(sensor: SensorConfig, zones=None) -> dict:
    """The sensor's per-zone values for the listed zones (float64 arrays), None where neutral.

    Parameters
    ----------
    sensor : SensorConfig
    zones : sequence of int, optional
        Flat zone indices (row-major) in output order (default all).

    Returns
    -------
    dict
        ``gains``, ``offsets_ps``, ``scales``, ``overlap_m``: ndarray of shape (Z,) or None.
    """
    idx = np.arange(sensor.n_zones) if zones is None else np.asarray(zones, dtype=int)
    out = {}
    for key, field, neutral in (("gains", "zone_gains", 1.0), ("offsets_ps", "zone_time_offsets_ps", 0.0),
                                ("scales", "zone_time_scales", 1.0), ("overlap_m", "zone_overlap_m", 0.0)):
        v = getattr(sensor, field)
        arr = None if v is None else np.asarray(v, dtype=np.float64)[idx]
        out[key] = None if arr is None or np.all(arr == neutral) else arr
    return out


def overlap_factor(times_ps, overlap_m):
    """Near-field overlap ``r^2 / (r^2 + d0^2)`` at the range ``r = c t / 2`` of arrival time ``t``.

    Parameters
    ----------
    times_ps : array, shape (...)
        Arrival times, ps (``t <= 0`` gives 0 unless ``d0 = 0``).
    overlap_m : array, broadcastable to ``times_ps``
        Overlap distance ``d0``, metres (>= 0; 0 gives 1).

    Returns
    -------
    array, shape (...)
        In [0, 1]; 1/2 at ``r = d0``; ``1 - (d0 / r)^2`` to first order far away.
    """
    r = 0.5 * C_M_PER_PS * jnp.clip(jnp.asarray(times_ps), 0.0, None)
    d0 = jnp.asarray(overlap_m)
    r2 = r * r
    den = r2 + d0 * d0
    return jnp.where(den > 0, r2 / jnp.where(den > 0, den, 1.0), 1.0)


def move_nodes(nodes, node_times_ps, node_width_ps, *, scales=None, offsets_ps=None):
    """Move each row of a node transient to the zone's recorded time ``s_z t + delta_z``.

    Parameters
    ----------
    nodes : array, shape (Z, K)
    node_times_ps : array, shape (K,)
        Node times (uniform spacing ``node_width_ps``).
    node_width_ps : scalar
    scales, offsets_ps : array of shape (Z,) or None

    Returns
    -------
    array, shape (Z, K)
        Each node's content split linearly between the two nodes nearest its new
        time, as :func:`~nlosplan.sensor_models.transient.deposit_at` does (mass and
        mean time preserved, added spread at most a quarter node squared); content
        moved off the grid is lost.
    """
    x = jnp.asarray(nodes)
    t = jnp.asarray(node_times_ps, x.dtype)[None, :]
    new = t
    if scales is not None:
        new = new * jnp.asarray(scales, x.dtype)[:, None]
    if offsets_ps is not None:
        new = new + jnp.asarray(offsets_ps, x.dtype)[:, None]
    new = jnp.broadcast_to(new, x.shape)
    pos = (new - t[:, :1]) / node_width_ps
    z, k = x.shape
    i0f = jnp.floor(pos)
    f = pos - i0f
    i0 = jnp.clip(i0f, -2, k + 1).astype(jnp.int32)
    rows = jnp.broadcast_to(jnp.arange(z, dtype=jnp.int32)[:, None], x.shape)
    big = z * k
    idx0 = jnp.where((i0 >= 0) & (i0 < k), rows * k + i0, big)
    idx1 = jnp.where((i0 + 1 >= 0) & (i0 + 1 < k), rows * k + i0 + 1, big)
    out = jnp.zeros((big,), x.dtype)
    out = out.at[idx0.ravel()].add((x * (1.0 - f)).ravel(), mode="drop")
    out = out.at[idx1.ravel()].add((x * f).ravel(), mode="drop")
    return out.reshape(z, k)


def apply_zone_terms(nodes, node_times_ps, node_width_ps, *, gains=None, offsets_ps=None, scales=None,
                     overlap_m=None, overlap: bool = True):
    """Per-zone gain, near-field overlap, time scale and offset on a node transient.

    Parameters
    ----------
    nodes : array, shape (Z, K)
        Photons per iteration per node (rows: zones).
    node_times_ps : array, shape (K,)
        Node times, ps.
    node_width_ps : scalar
        Node spacing, ps.
    gains, offsets_ps, scales, overlap_m : array of shape (Z,) or None
        Per-zone values of these rows (None: neutral, nothing computed).
    overlap : bool
        Apply the overlap (False for crosstalk).

    Returns
    -------
    array, shape (Z, K)
    """
    x = jnp.asarray(nodes)
    if overlap and overlap_m is not None:
        x = x * overlap_factor(jnp.asarray(node_times_ps)[None, :], jnp.asarray(overlap_m, x.dtype)[:, None])
    if gains is not None:
        x = x * jnp.asarray(gains, x.dtype)[:, None]
    if offsets_ps is not None or scales is not None:
        x = move_nodes(x, node_times_ps, node_width_ps, scales=scales, offsets_ps=offsets_ps)
    return x


def apply_zone_terms_arrivals(times_ps, weights, *, gains=None, offsets_ps=None, scales=None, overlap_m=None):
    """The same terms on arrivals of shape (..., Z, K) (exact: no node grid).

    Returns
    -------
    times_ps, weights : array, shape (..., Z, K)
        Times ``s_z t + delta_z``, weights times gain and overlap.
    """
    t = jnp.asarray(times_ps)
    w = jnp.asarray(weights)
    if overlap_m is not None:
        w = w * overlap_factor(t, jnp.asarray(overlap_m, w.dtype)[:, None])
    if gains is not None:
        w = w * jnp.asarray(gains, w.dtype)[:, None]
    if scales is not None:
        t = t * jnp.asarray(scales, t.dtype)[:, None]
    if offsets_ps is not None:
        t = t + jnp.asarray(offsets_ps, t.dtype)[:, None]
    return t, w


def walk_shift_ps(flux, walk_ps):
    """Time shift (ps, negative = earlier) of a zone with ``flux`` signal photons per iteration.

    ``-w log10(flux)`` with ``log10(flux)`` held within ``[-WALK_DECADES, WALK_DECADES]``
    (so ``|shift| <= walk_reach_ps(w)``); differentiable in ``flux`` inside that range.
    """
    decades = jnp.clip(jnp.log10(jnp.maximum(jnp.asarray(flux), 1e-30)), -WALK_DECADES, WALK_DECADES)
    return -jnp.asarray(walk_ps) * decades


def walk_reach_ps(walk_ps: float) -> float:
    """Largest time shift (ps, either way) that a time walk of ``walk_ps`` per decade can give."""
    return abs(float(walk_ps)) * WALK_DECADES


def window_light(nodes, node_times_ps, start_ps, window_ps):
    """Photons per iteration of each row of a node transient at times inside ``[start, start + window)``, (Z,)."""
    t = jnp.asarray(node_times_ps)
    inside = (t >= start_ps) & (t < start_ps + window_ps)
    return jnp.sum(jnp.where(inside[None, :], jnp.asarray(nodes), 0.0), axis=-1)
