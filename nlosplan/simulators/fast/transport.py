"""Flash-LiDAR light transport in JAX: first bounce and three-bounce returns.

Pure functions of a plan's static structure (hashable, the jit cache key),
its arrays, and the dynamic scene and sensor parameters; ``jit``, ``vmap``
and ``grad`` apply. Units: metres, picoseconds, unit flash power.

Notes
-----
Wall cell ``i`` lit by the flash (power ``I dOmega`` on area ``A``) has
radiance ``L_i = (rho_w / pi) I dOmega / A``. An object point ``x`` (area
``dA``) receives ``E(x) = sum_i L_i C(x, i)`` with ``C`` the coupling of
:mod:`~nlosplan.simulators.fast.coupling`.

- Lambertian object (albedo ``rho``): radiance ``rho / pi E(x)`` lights
  detection cell ``j`` of zone ``z``, which returns
  ``(rho_w / pi) s dOmega_j / A_j * C(x, j) * rho / pi * E(x) dA`` along
  paths of length ``r_i + d_i + d_j + r_j``. The two legs are deposited on
  time grids per sample, convolved and summed over the samples
  (:func:`~nlosplan.sensor_models.transient.sum_convolve`), so the full double
  integral costs ``M (N1 + N2)`` path evaluations, not ``M N1 N2``.
- Retroreflective object (the confocal shortcut ``x2 ~ x1`` of DENALI's
  Eq. 1): the power ``rho E_i(x) dA`` from cell ``i`` returns to cell ``i``
  in a Gaussian lobe; the zone containing the lobe's landing spot collects
  ``(rho_w / pi) s cos / r^2`` of it, along ``2 (r_i + d_i)``. With a lobe
  of non-zero width the share of each zone is the lobe's Gaussian mass over
  the zone's tangent-plane rectangle (spread ``d_i sigma`` mapped by the
  wall-to-image Jacobian; at grazing elevations below ``GRAZING_SIGMAS``
  lobe widths the spread is held at its value there). Integrated over a zone footprint the return
  falls as ``1/d^2``; point-wise (a lobe wider than a zone) as ``1/d^4``.
"""

from __future__ import annotations

import math

from nlosplan._jax import jax, jnp
from nlosplan.constants import C_M_PER_PS, MAX_COUNT_24BIT
from nlosplan.sensor_models.binning import bin_impulses
from nlosplan.sensor_models.impulse import impulse_sigma_ps
from nlosplan.sensor_models.noise import floor_rate_hz, per_bin
from nlosplan.sensor_models.pipeline import counts_from_rates
from nlosplan.sensor_models.transient import (RowPattern, bin_nodes_without_irf, deposit, deposit_at, deposit_method,
                                              deposit_sum_convolve, irf_matrix)
from nlosplan.sensor_models.zone_terms import apply_zone_terms, move_nodes, walk_shift_ps, window_light
from nlosplan.simulators.fast.coupling import _dot, far_coupling, polygon_coupling

#: Elevations (of the object-to-wall ray above the wall plane) below this many lobe sigmas hold the lobe spread.
GRAZING_SIGMAS = 3.0


def _pose(p):
    """Surface points and normals of an object in the world, (M, 3) each."""
    r, t = p["to_world"][:3, :3], p["to_world"][:3, 3]
    return p["points"] @ r.T + t, p["normals"] @ r.T


def _coupling(a, p, leg: str, x, n, n_near: int):
    """Coupling (M, N) and distance (M, N) between samples and the wall cells of a leg.

    The scene's near-wall cells ``p["near{leg}"]`` (a padded block of
    ``n_near`` indices) use the exact polygon form factor where a sample is
    closer than the cell's threshold ``thr``; padding indices are out of
    range and dropped.

    Returns
    -------
    coupling, dist : array, shape (M, N)
    near : tuple or None
        ``(idx (K,), use (M, K), exact (M, K))`` for the near block.
    """
    height = (x - a["w0"]) @ a["n_w"]
    c, dist = far_coupling(a[f"c{leg}t"], a[f"a{leg}"], x, n, height)
    if not n_near:
        return c, dist, None
    idx = p[f"near{leg}"]
    valid = idx < c.shape[1]
    exact = p[f"exact{leg}"] if f"exact{leg}" in p else _exact_coupling(a, leg, x, n, idx)
    use = (jnp.take(dist, idx, axis=1, mode="clip") < jnp.take(a[f"thr{leg}"], idx, mode="clip")[None]) & valid
    c = c.at[:, idx].set(jnp.where(use, exact, jnp.take(c, idx, axis=1, mode="clip")), mode="drop")
    return c, dist, (idx, use, exact)


def _exact_coupling(a, leg: str, x, n, idx):
    """Exact polygon coupling (M, K) between samples and the near-wall block ``idx`` (K,) of a leg's cells."""
    return polygon_coupling(x, n, jnp.take(a[f"k{leg}"], idx, axis=0, mode="clip"))


def with_exact_couplings(static, arrays, scene_p, terms=None):
    """A batch's scene parameters (leading axis: scenes) with every term's near-wall couplings computed beforehand.

    The exact polygon coupling (:func:`_coupling`) of a near-wall block is a few hundred small elementwise
    operations on a (samples, K) array: scene by scene (``lax.map``), each costs more to dispatch than to
    compute. Batched over the scenes (``vmap``) they run ~3x faster (DENALI's mount and plate: 0.046 and 0.054
    -> 0.016 and 0.013 ms a scene) and give the same values (elementwise; the bench's models and the design's
    layouts give the same histograms to the bit, tested in ``tests/test_fast_batching.py``). Added as
    ``"exact1"`` / ``"exact2"`` (scenes, M, K) to the terms that have near blocks; :func:`_coupling` uses them.

    Parameters
    ----------
    terms : iterable of int, optional
        Only these object terms (indices into ``static.objects``; default all): the ones the batch computes.
    """
    objects = []
    for k, (st, a, p) in enumerate(zip(static.objects, arrays["objects"], scene_p["objects"])):
        p = dict(p)
        for leg, n_near in (("1", st.near1), ("2", st.near2)):
            if n_near and (terms is None or k in terms):
                p[f"exact{leg}"] = jax.vmap(
                    lambda q, leg=leg, a=a: _exact_coupling(a, leg, *_pose(q), q[f"near{leg}"]))(p)
        objects.append(p)
    return {**scene_p, "objects": objects}


def _near_point(a, leg: str, x, near):
    """Where a near-wall pair's light meets the wall, and the share of the pair that it stands for.

    A sample close to the wall compared with a cell (height ``h``, cell size
    ``a``) sees the cell's light come mostly from the part under it, not
    from its centre: that point is the sample's foot on the wall clamped
    into the cell. Its share ``1 / (1 + (h/a)^4) / (1 + (rho/a)^2)`` (``rho``
    the foot's distance outside the cell) is all of the pair when the object
    nearly touches the wall above the cell, half at ``h = a``, almost none a
    few cell sizes away or aside, where the cell is lit evenly.

    Returns
    -------
    land : tuple of 3 arrays, shape (M, K) each
        The near points' x, y and z (component by component: on CPUs this vectorises far better than a
        trailing axis of 3, see :func:`~nlosplan.simulators.fast.coupling.far_coupling`).
    share : array, shape (M, K)
        0 for pairs that do not use the exact coupling (and padding).
    """
    idx, use, _ = near
    h = (x - a["w0"]) @ a["n_w"]
    foot = x - h[:, None] * a["n_w"][None]
    fu, fv = (foot - a["w0"]) @ a["wall_u"], (foot - a["w0"]) @ a["wall_v"]
    box = jnp.take(a[f"box{leg}"], idx, axis=0, mode="clip")  # (K, 4): u min, u max, v min, v max
    lu = jnp.clip(fu[:, None], box[None, :, 0], box[None, :, 1])
    lv = jnp.clip(fv[:, None], box[None, :, 2], box[None, :, 3])
    land = tuple(a["w0"][k] + lu * a["wall_u"][k] + lv * a["wall_v"][k] for k in range(3))
    size2 = jnp.take(a[f"a{leg}"], idx, mode="clip")[None]
    ratio2 = h[:, None] ** 2 / size2
    rho2 = ((fu[:, None] - lu) ** 2 + (fv[:, None] - lv) ** 2) / size2
    return land, jnp.where(use, 1.0 / ((1.0 + ratio2 * ratio2) * (1.0 + rho2)), 0.0)


def _minus(v, b):
    """Components of ``v - b`` for ``v`` a tuple of 3 (M, K) arrays and ``b`` a point (3,) or points (M, 3)."""
    if b.ndim == 1:
        return tuple(v[k] - b[k] for k in range(3))
    return tuple(v[k] - b[:, k, None] for k in range(3))


def _norm(v):
    """Length of a vector given as a tuple of 3 arrays."""
    return jnp.sqrt(_dot(v, v))


def _near_path(a, leg: str, x, near, path):
    """Path lengths (M, N) with near pairs moved towards their near point (share-weighted mean)."""
    idx = near[0]
    land, share = _near_point(a, leg, x, near)
    at_land = _norm(_minus(land, a["lidar"][0])) + _norm(_minus(land, x))
    old = jnp.take(path, idx, axis=1, mode="clip")
    return path.at[:, idx].set(share * at_land + (1.0 - share) * old, mode="drop")


def _retro_near(st, a, p, x, near, grid, bw, t0):
    """Retro returns of the near-wall pairs' share that lands under the object: (Zobj, n_r).

    The retroreflected light goes straight back to where it came from: the
    pair's near point (see :func:`_near_point`), seen by its cell's zone (the
    lobe, ``h sigma`` wide, is a point at this range), with ``s cos / r^2``.
    """
    idx, use, exact = near
    land, share = _near_point(a, "1", x, near)
    lid = a["lidar"]  # rows: position, right, up, forward
    q = _minus(land, lid[0])
    r = _norm(q)
    fwd = jnp.maximum(_dot(q, lid[3]), 0.0)
    # cells inside the field of view are zone-aligned: the landing point's zone is its cell's (-1: not computed)
    zrow = jnp.take(a["cell_row"], idx, mode="clip")[None]
    ok = use & (zrow >= 0)
    recv = a["wall_rho_pi"] * (fwd / r) ** a["sens_power"] * jnp.maximum(-_dot(q, a["n_w"]), 0.0) / (r * r * r)
    w = jnp.take(a["l1"], idx, mode="clip")[None] * exact * share * (p["albedo"] * p["areas"][:, None]) * recv
    dl = _norm(_minus(land, x))
    pos = grid.node_position(2.0 * (r + dl) / C_M_PER_PS, bw, t0) - a["k_r0"]
    rows = RowPattern(jnp.maximum(zrow[0], 0), 0)  # a row per cell (its zone)
    return deposit_at(pos, jnp.where(ok, w, 0.0), rows, st.n_rows, st.n_r)


def _lobe_fractions(a, x, w, sigma):
    """Share of each cell's retro lobe landing in each object zone, shape (N1, Zobj).

    The lobe's spread is evaluated at the distance from each cell to the
    object's centroid weighted by ``w`` (the area of samples that see the wall).
    """
    centroid = (x * w[:, None]).sum(0) / jnp.maximum(w.sum(), 1e-30)
    e = a["c1t"].T - centroid
    dbar = jnp.sqrt(jnp.sum(e * e, -1))
    e = e / dbar[:, None]
    n_w = a["n_w"]
    # first-order spread ~ 1 / sin(elevation above the wall); below GRAZING_SIGMAS lobe widths of elevation the
    # landing spot is heavy-tailed, not Gaussian, and the spread is held at its value there
    en = jnp.minimum(e @ n_w, -jnp.sin(GRAZING_SIGMAS * sigma))
    jac = a["jac"]  # (N1, 2, 3)
    jp = jac - (jac @ e[:, :, None]) / en[:, None, None] * n_w[None, None, :]
    spread = dbar[:, None] * sigma * jnp.sqrt(jnp.sum(jp * jp, -1))  # (N1, 2)
    ones = jnp.ones((e.shape[0], 1), x.dtype)
    fu = bin_impulses(a["uv"][:, :1], ones, a["u_edges"], spread[:, 0, None, None])  # (N1, cols)
    fv = bin_impulses(-a["uv"][:, 1:], ones, a["nv_edges"], spread[:, 1, None, None])  # (N1, rows)
    full = (fv[:, :, None] * fu[:, None, :]).reshape(e.shape[0], -1)
    return full[:, a["obj_zones"]]


def _retro(st, a, p, grid, bw, t0):
    x, n = _pose(p)
    c, dist, near = _coupling(a, p, "1", x, n, st.near1)
    w = a["l1"][None] * c * (p["albedo"] * p["areas"][:, None]) * a["recv"][None]
    if near is not None:  # near-wall pairs land (in part) under the object, see _retro_near
        share = jnp.zeros_like(w).at[:, near[0]].add(_near_point(a, "1", x, near)[1], mode="drop")
        w = w * (1.0 - share)
    t = 2.0 * (a["r1"][None] + dist) / C_M_PER_PS
    pos = grid.node_position(t, bw, t0) - a["k_r0"]
    n1 = a["a1"].shape[0]
    per_cell = deposit_at(pos, w, RowPattern(jnp.arange(n1), 0), n1, st.n_r)  # a row per cell: (N1, n_r)
    # lobe spread at the centroid of the samples that see the wall (independent of which cells are kept)
    sees = jnp.max((a["wall_corners"][None] - x[:, None]) @ n[:, :, None], axis=(1, 2)) > 0
    seen_area = p["areas"] * (sees & ((x - a["w0"]) @ a["n_w"] > 0))
    frac = _lobe_fractions(a, x, seen_area, a["lobe_sigma"]) if st.lobe else a["frac"]
    out = frac.T @ per_cell
    if near is not None:
        out = out + _retro_near(st, a, p, x, near, grid, bw, t0)
    return out, a["k_r0"]


def _lambertian(st, a, p, grid, bw, t0):
    x, n = _pose(p)
    m = x.shape[0]
    delta = bw / grid.oversample
    c1, d1, near1 = _coupling(a, p, "1", x, n, st.near1)
    path1 = a["r1"][None] + d1
    if near1 is not None:
        path1 = _near_path(a, "1", x, near1, path1)
    t1 = path1 / C_M_PER_PS
    # a row per sample, in the (samples, cells) layout the arrivals are computed in (cell by cell made XLA compute
    # the legs transposed: the object's diffuse term 0.131 -> 0.107 ms a scene); the kernel takes four samples at
    # once, position by position, so consecutive adds go to different rows and each row takes its cells in the same
    # order as before: the same sums
    rows1 = RowPattern(jnp.zeros((c1.shape[1],), jnp.int32), 1)
    leg1 = deposit_at((t1 - t0) / delta - 0.5 - a["j1"], a["l1"][None] * c1, rows1, m, st.n1)
    c2, d2, near2 = _coupling(a, p, "2", x, n, st.near2)
    w2 = a["l2"][None] * c2 * (p["albedo"] / math.pi) * p["areas"][:, None]
    path2 = d2 + a["r2"][None]
    if near2 is not None:
        path2 = _near_path(a, "2", x, near2, path2)
    t2 = path2 / C_M_PER_PS
    rows2 = RowPattern(a["row2"], st.n_rows)  # a row per sample and zone
    # the detection leg deposited and convolved in one step (the kernels never hold its (m, zones, n2) array)
    return jnp.maximum(deposit_sum_convolve(leg1, t2 / delta - a["j2"], w2, rows2, st.n2, st.fft_len), 0.0), a["shift"]


def _place(out, shift, n_nodes):
    """Put a (rows, L) block starting at node ``shift`` of an (rows, n_nodes) grid (clipped)."""
    length = out.shape[1]
    buf = jnp.zeros((out.shape[0], n_nodes + 2 * length), out.dtype)
    start = (jnp.clip(shift, -length, n_nodes) + length).astype(jnp.int32)
    buf = jax.lax.dynamic_update_slice(buf, out, (jnp.int32(0), start))
    return buf[:, length : length + n_nodes]


def object_nodes(static, arrays, scene_p, bw, t0, terms=None):
    """Three-bounce photons per iteration per unit photon scale on the node grid, (Z, n_nodes).

    Parameters
    ----------
    terms : tuple of int, optional
        Only these object terms (indices into ``static.objects``; default all). The nodes are a sum over
        terms, so the terms can be computed apart and added (see :func:`scene_counts`'s ``shared``).
    """
    grid = static.grid
    total = jnp.zeros((static.n_zones, grid.n_nodes), bw.dtype)
    for k, (st, a, p, rows) in enumerate(zip(static.objects, arrays["objects"], scene_p["objects"],
                                             static.object_rows)):
        if terms is not None and k not in terms:
            continue
        fn = _retro if st.kind == "retroreflective" else _lambertian
        out, shift = fn(st, a, p, grid, bw, t0)
        total = total.at[jnp.asarray(rows)].add(_place(out, shift, grid.n_nodes))
    return total


def zone_nodes(static, arrays, nodes, bw, t0, overlap: bool = True):
    """The sensor's per-zone gain, overlap and time offset on node transients (Z, n_nodes) (none: unchanged)."""
    if not static.zone_terms:
        return nodes
    grid = static.grid
    return apply_zone_terms(nodes, grid.node_times(bw, t0), bw / grid.oversample, overlap=overlap, **arrays["zone"])


def to_bins(static, terms: dict, nodes):
    """Node transients ``(Z, n_nodes)`` binned through the sensor's impulse response: ``(Z, n_bins)``."""
    if static.irf == "none":
        return bin_nodes_without_irf(static.grid, nodes)
    return nodes @ terms["irf"]


def sensor_terms(static, arrays, sensor_p) -> dict:
    """What a sensor adds independently of the hidden objects (shared by every scene of a batch).

    Returns
    -------
    dict of arrays
        ``sp`` (the sensor fields as arrays), ``irf`` (the node -> bin matrix of the impulse response,
        ``(n_nodes, n_bins)``, absent when there is none: see :func:`to_bins`), ``direct`` and
        ``crosstalk`` (photons per iteration per bin, ``(Z, n_bins)``; the direct part already scaled by
        the photon scale). Arrays only, so a batch can compute them once and pass them in.
    """
    grid = static.grid
    dtype = arrays["direct_w"].dtype
    sp = {k: jnp.asarray(v, dtype) for k, v in sensor_p.items()}
    bw, t0 = sp["bin_width_ps"], sp["start_offset_ps"]
    z = static.n_zones
    out = {"sp": sp}
    if static.irf != "none":
        sigma = impulse_sigma_ps(sp["pulse_fwhm_ps"], sp["jitter_fwhm_ps"]) if static.irf == "full" else jnp.zeros((), dtype)
        pulse = None
        if static.pulse is not None:
            pulse = (jnp.asarray(static.pulse[0], dtype), static.pulse[1], jnp.asarray(static.pulse[2], dtype))
        out["irf"] = irf_matrix(grid, bin_width_ps=bw, sigma_ps=sigma, pulse=pulse, extent_ps=static.extent,
                                nominal_bin_width_ps=static.nominal_bin_width)
    zero = jnp.zeros((z, static.grid.n_bins), dtype)
    direct = xt = zero
    if static.direct:
        nodes = deposit(grid, arrays["direct_path"] / C_M_PER_PS, arrays["direct_w"], arrays["direct_row"], z,
                        bin_width_ps=bw, start_offset_ps=t0)
        direct_nodes = sp["photon_scale"] * zone_nodes(static, arrays, nodes, bw, t0)
        direct = to_bins(static, out, direct_nodes)
    if static.crosstalk:
        nodes = deposit(grid, jnp.zeros((z,), dtype), jnp.broadcast_to(sp["crosstalk"], (z,)), jnp.arange(z), z,
                        bin_width_ps=bw, start_offset_ps=t0)
        xt_nodes = zone_nodes(static, arrays, nodes, bw, t0, overlap=False)
        xt = to_bins(static, out, xt_nodes)
    out.update(direct=direct, crosstalk=xt)
    if static.walk_ps:  # the time walk depends on each scene's total light: keep the unbinned nodes
        zero_nodes = jnp.zeros((z, grid.n_nodes), dtype)
        out["direct_nodes"] = direct_nodes if static.direct else zero_nodes
        out["crosstalk_nodes"] = xt_nodes if static.crosstalk else zero_nodes
    return out


def _scene_nodes(static, arrays, scene_p, bw, t0, shared):
    """All object terms of a scene on the node grid, (Z, n_nodes); ``shared = (terms, nodes)`` adds precomputed ones."""
    if shared is None:
        return object_nodes(static, arrays, scene_p, bw, t0)
    done, nodes = shared
    rest = tuple(k for k in range(len(static.objects)) if k not in done)
    return object_nodes(static, arrays, scene_p, bw, t0, terms=rest) + nodes


def scene_counts(static, arrays, scene_p, terms: dict, parts: bool = False, shared=None):
    """Expected counts of one scene given its sensor's :func:`sensor_terms` (see :func:`forward`).

    Parameters
    ----------
    shared : (tuple of int, array (Z, n_nodes)), optional
        Object terms already computed (:func:`object_nodes` with ``terms=``, e.g. a gantry mount that is
        the same in many scenes of a batch) and their nodes: added to the scene's other terms before the
        zone terms and the time walk, which mix a zone's light of every term.
    """
    sp = terms["sp"]
    dtype = arrays["direct_w"].dtype
    bw, t0 = sp["bin_width_ps"], sp["start_offset_ps"]
    if static.walk_ps:
        direct, obj, xt = _walked(static, arrays, scene_p, terms, bw, t0, shared)
    else:
        direct, xt = terms["direct"], terms["crosstalk"]
        obj = jnp.zeros_like(terms["direct"])
        if static.objects:
            obj = sp["photon_scale"] * to_bins(static, terms, zone_nodes(
                static, arrays, _scene_nodes(static, arrays, scene_p, bw, t0, shared), bw, t0))
    lam = direct + obj + xt
    # a pruned term is a Python 0.0 (folded when traced, no array operation)
    rate = floor_rate_hz(sp["dark_rate_hz"] if static.dark else 0.0, sp["ambient_rate_hz"] if static.ambient else 0.0,
                         jnp.asarray(scene_p["lights"], dtype) if static.ambient else 0.0)
    floor = per_bin(jnp.asarray(rate, dtype), bw)
    dead = None if static.dead_time_ps is None else static.dead_time_ps / bw
    counts = counts_from_rates(lam, iterations=sp["iterations"], floor_per_bin=floor, pileup=static.pileup,
                               max_count=MAX_COUNT_24BIT if static.saturation else None, spads=static.spads,
                               dead_bins=dead)
    if not parts:
        return counts
    it = sp["iterations"]
    return counts, {"direct": it * direct, "object": it * obj,
                    "floor": jnp.broadcast_to(it * floor, counts.shape), "crosstalk": it * xt}


def _walked(static, arrays, scene_p, terms, bw, t0, shared=None):
    """Direct, object and crosstalk photons per bin after the time walk of each zone's total light."""
    sp = terms["sp"]
    parts = [terms["direct_nodes"], jnp.zeros_like(terms["direct_nodes"]), terms["crosstalk_nodes"]]
    if static.objects:
        parts[1] = sp["photon_scale"] * zone_nodes(
            static, arrays, _scene_nodes(static, arrays, scene_p, bw, t0, shared), bw, t0)
    times = static.grid.node_times(bw, t0)
    shift = walk_shift_ps(sum(window_light(p, times, t0, bw * static.grid.n_bins) for p in parts), static.walk_ps)
    delta = bw / static.grid.oversample
    return tuple(to_bins(static, terms, move_nodes(p, times, delta, offsets_ps=shift)) for p in parts)


def forward(static, arrays, scene_p, sensor_p, parts: bool = False):
    """Expected counts of one scene seen by one sensor.

    Parameters
    ----------
    static : PlanStatic
    arrays : dict
        Plan arrays as JAX arrays.
    scene_p : dict
        ``{"objects": [{"to_world": (4, 4), "albedo": (), "points": (M, 3),
        "normals": (M, 3), "areas": (M,)}...], "lights": ()}``.
    sensor_p : dict
        The dynamic sensor fields (scalars), see ``DYNAMIC_SENSOR_FIELDS``.
    parts : bool
        Also return the linear parts (expected counts before pile-up and clip).

    Returns
    -------
    counts : array, shape (Z, n_bins)
    parts : dict of arrays, shape (Z, n_bins) (only if ``parts``)
        ``direct``, ``object``, ``floor`` (dark + ambient: :mod:`~nlosplan.sensor_models.noise`), ``crosstalk``.

    Notes
    -----
    ``sensor_terms`` (impulse-response matrix, first bounce, crosstalk)
    then ``scene_counts`` (the objects); a batch computes the first once.
    """
    with deposit_method(static.deposit):
        return scene_counts(static, arrays, scene_p, sensor_terms(static, arrays, sensor_p), parts)
