"""Expected counts and their derivatives with respect to an object displacement and nuisance parameters (fast backend).

Central differences of the transport in float64: the objects' light is computed at the five displacements
``0, +-step`` of each axis on the node grid, and the nuisances (photon scale, the floor's ambient and dark rates,
the object's albedo) are scaled on the sensor's terms and the undisplaced light, so a nuisance costs a pass through
the zone terms and the binning, not a new transport. The seam is
:func:`nlosplan.simulators.counts_and_jacobian` (inputs checked there); the Cramér–Rao bound
(:mod:`nlosplan.tasks.bounds`), the design planner's bound scenes and the capture planner's counts model use it.
"""

from __future__ import annotations

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.transient import deposit_method
from nlosplan.simulators.fast.simulator import FastSimulator, to_jax
from nlosplan.simulators.fast.transport import object_nodes, scene_counts, sensor_terms
from nlosplan.simulators.result import CountsJacobian

__all__ = ["LOG_STEP", "POSITION_STEP_M", "counts_and_jacobian"]

#: The sensor field each nuisance scales (the albedo scales the first object term instead: see :func:`_lam_jac`).
_SENSOR_FIELD = {"photon_scale": "photon_scale", "ambient": "ambient_rate_hz", "dark": "dark_rate_hz"}

#: Steps of the central differences: 10 nm in the position (metres), 1e-8 in the log of a nuisance. Far
#: below any length of the scene (a time-grid node is ~7 mm of path), far above float64 rounding (~1e-16 m per
#: metre of pose).
POSITION_STEP_M = 1e-8
LOG_STEP = 1e-8
#: One-sided differences that disagree by more than this share are a kink or a jump between them (see
#: :func:`_slopes`).
_SIDES_RTOL = 1e-3


def _moved(scene_p, axes, pos):
    """The scene's object terms moved by ``pos @ axes`` (metres)."""
    shift = pos[0] * axes[0] + pos[1] * axes[1]
    return {**scene_p, "objects": [dict(o, to_world=o["to_world"].at[:3, 3].add(shift)) for o in scene_p["objects"]]}


def _scaled(terms, names, nu):
    """The sensor's terms with the nuisances scaled by ``exp(nu)`` (albedo excepted: see :func:`_lam_jac`).

    The photon scale scales the direct return (linear in it) and the objects' light through ``sp``; the
    ambient and dark rates enter through ``sp``.
    """
    terms, sp = dict(terms), dict(terms["sp"])
    for k, name in enumerate(names):
        factor = jnp.exp(nu[k])
        if name == "photon_scale":
            sp["photon_scale"] = sp["photon_scale"] * factor
            for key in ("direct", "direct_nodes"):
                if key in terms:
                    terms[key] = terms[key] * factor
        elif name != "albedo":
            sp[_SENSOR_FIELD[name]] = sp[_SENSOR_FIELD[name]] * factor
    terms["sp"] = sp
    return terms


def _slopes(lam0, up, down, step):
    """d lam / d theta from counts at ``theta`` and ``theta +- step`` along one parameter, (Z, B) each.

    The central difference where the two one-sided differences agree (within ``_SIDES_RTOL`` and rounding);
    where they do not, a kink (a path's arrival crossing a time-grid node, the 24-bit clip) or a jump (a
    sample crossing a switch, e.g. the near-wall coupling's threshold) lies within the step, and the smaller
    one-sided difference is taken: the slope on the side without the jump, as forward-mode differentiation
    would give (the central difference across a jump is ``jump / (2 step)``, not a slope).
    """
    right, left = (up - lam0) / step, (lam0 - down) / step
    rounding = 64 * jnp.finfo(lam0.dtype).eps * (jnp.abs(lam0) + jnp.abs(up) + jnp.abs(down)) / step
    agree = jnp.abs(right - left) <= _SIDES_RTOL * jnp.maximum(jnp.abs(right), jnp.abs(left)) + rounding
    return jnp.where(agree, 0.5 * (right + left), jnp.where(jnp.abs(right) < jnp.abs(left), right, left))


def _position_points(theta, step):
    """The five displacements ``theta[:2]``, ``+- step`` along each axis: (5, 2), rows 0, +x, +y, -x, -y."""
    eye = jnp.eye(2, dtype=theta.dtype) * step
    return theta[None, :2] + jnp.concatenate([jnp.zeros((1, 2), theta.dtype), eye, -eye])


def _nodes_at(static, arrays, scene_p, axes, points, bw, t0, terms):
    """Object ``terms`` of one scene on the node grid at each displacement of ``points``, (5, Z, n_nodes)."""
    return jax.lax.map(lambda pos: object_nodes(static, arrays, _moved(scene_p, axes, pos), bw, t0, terms=terms),
                       points)


def _term_nodes(static, arrays, scenes_p, sensor_p, axes, theta, steps, only):
    """Object terms ``only`` of each scene at the five displacements, (N, 5, Z, n_nodes) (see :func:`_lam_jac`)."""
    bw, t0 = sensor_p["bin_width_ps"], sensor_p["start_offset_ps"]
    points = _position_points(theta, steps[0])
    with deposit_method(static.deposit):
        return jax.lax.map(lambda sc: _nodes_at(static, arrays, sc, axes, points, bw, t0, only), scenes_p)


def _lam_jac(static, names, arrays, scenes_p, sensor_p, axes, theta, steps, shared, shared_nodes):
    """Counts (N, Z, B) and their Jacobian (N, Z, B, P) at ``theta`` for a batch of scenes.

    Central differences with ``steps`` (P,) per parameter (:func:`_slopes`). Only the displacements move the
    objects: their light is computed at the five displacements ``0, +-step`` on each axis (the terms in
    ``shared`` come precomputed, ``shared_nodes`` (N, 5, Z, n_nodes): a gantry's mount is the same under
    every object at a position), and the nuisances' ``+-step`` reuse the undisplaced light on the node grid
    (the albedo scales the first term's, which is linear in it). Forward-mode differentiation (``jvp`` over
    the parameters) gave the same bounds to 6e-5 per scene (float64, calibrated 1x1, 3x3 and 8x8 layouts, 60
    DENALI scenes) and took 3-12 times longer to compile (3x3: 20.6 s against 6.3 s, 8x8: 40.7 s against 3.4 s).
    """
    q = theta.size - 2  # nuisances
    with deposit_method(static.deposit):
        terms = sensor_terms(static, arrays, sensor_p)  # the same for every scene and every displacement
        bw, t0 = terms["sp"]["bin_width_ps"], terms["sp"]["start_offset_ps"]
        rest = tuple(k for k in range(len(static.objects)) if k not in shared)
        every = tuple(range(len(static.objects)))
        points = _position_points(theta, steps[0])
        albedo = names.index("albedo") if "albedo" in names else None

        def one(args):
            sc, done = args
            if albedo is not None:  # at theta's albedo (the first term is never in ``shared`` then)
                obj = dict(sc["objects"][0], albedo=sc["objects"][0]["albedo"] * jnp.exp(theta[2 + albedo]))
                sc = {**sc, "objects": [obj] + list(sc["objects"][1:])}
            nodes = _nodes_at(static, arrays, sc, axes, points, bw, t0, rest) + done
            evals = [(nodes[i], theta[2:]) for i in range(5)]
            if albedo is not None:
                term0 = object_nodes(static, arrays, _moved(sc, axes, points[0]), bw, t0, terms=(0,))
            for sign in (1.0, -1.0):
                for j in range(q):
                    nu = theta[2:].at[j].add(sign * steps[2 + j])
                    n0 = nodes[0]
                    if j == albedo:
                        n0 = n0 + (jnp.exp(nu[j] - theta[2 + j]) - 1.0) * term0
                    evals.append((n0, nu))
            stacked = (jnp.stack([e[0] for e in evals]), jnp.stack([e[1] for e in evals]))
            lam = jax.lax.map(lambda e: scene_counts(static, arrays, sc, _scaled(terms, names, e[1]),
                                                     shared=(every, e[0])), stacked)
            # rows: 0; +x, +y, -x, -y; +nu_k ..., -nu_k ...
            cols = [_slopes(lam[0], lam[1 + k], lam[3 + k], 0.5 * (points[1 + k, k] - points[3 + k, k]))
                    for k in range(2)]
            cols += [_slopes(lam[0], lam[5 + j], lam[5 + q + j], steps[2 + j]) for j in range(q)]
            return lam[0], jnp.stack(cols, axis=-1)

        return jax.lax.map(one, (scenes_p, shared_nodes))


_TERM_NODES = jax.jit(_term_nodes, static_argnums=(0, 7))
_LAM_JAC = jax.jit(_lam_jac, static_argnums=(0, 1, 8))


def counts_and_jacobian(scenes, sensor: SensorConfig, *, fidelity="default", names=("photon_scale",), axes,
                        zones=None, theta=None, chunk: int = 25, progress=None) -> CountsJacobian:
    """Expected counts and their derivatives, by the fast backend (see :func:`nlosplan.simulators.counts_and_jacobian`).

    Parameters
    ----------
    scenes : list of Scene
        Scenes of one rig (see :class:`~nlosplan.simulators.fast.simulator.FastSimulator`).
    sensor : SensorConfig
    fidelity : str, dict or Fidelity
    names : tuple of str
        Nuisance parameters, checked, from :data:`~nlosplan.simulators.backend.NUISANCE_PARAMETERS`.
    axes : ndarray, shape (2, 3)
        Orthonormal world directions of the two displacements (checked).
    zones, theta, chunk, progress
        As :func:`nlosplan.simulators.counts_and_jacobian`.

    Returns
    -------
    CountsJacobian
        Central differences of ``POSITION_STEP_M`` and ``LOG_STEP`` (see :func:`_lam_jac`).
    """
    ax = jnp.asarray(axes)
    sim = FastSimulator(scenes, sensor, fidelity=fidelity, zones=zones, dtype="float64", chunk=chunk)
    scene_p, sensor_p = sim.params()
    scene_p = to_jax(scene_p, jnp.float64)
    sensor_p = jax.tree_util.tree_map(lambda a: a[0], to_jax(sensor_p, jnp.float64))
    arrays = to_jax(sim.plan.arrays, jnp.float64)
    t = jnp.zeros(2 + len(names)) if theta is None else jnp.asarray(theta, jnp.float64).reshape(2 + len(names))
    steps = jnp.asarray([POSITION_STEP_M] * 2 + [LOG_STEP] * len(names), jnp.float64)
    static, n = sim.plan.static, len(scenes)
    chunks = [np.arange(start, start + sim.chunk).clip(max=n - 1) if n > sim.chunk else np.arange(n)
              for start in range(0, n, sim.chunk)]  # padded chunks of one shape: one compilation
    share = sim.shared_terms()  # e.g. the mount: the same in every scene at a position, computed once per pose
    # theta's albedo scales the first term: not shared then
    only = () if share is None else tuple(k for k in share[0] if not (k == 0 and "albedo" in names))
    table = group = None
    if only:
        _, first, group = share
        parts = []
        for s0 in range(0, len(first), sim.chunk):  # chunks of the scenes' shape
            pick = first[np.arange(s0, s0 + sim.chunk).clip(max=len(first) - 1)]
            part = jax.tree_util.tree_map(lambda a: a[pick], scene_p)
            parts.append(np.asarray(_TERM_NODES(static, arrays, part, sensor_p, ax, t, steps, only))[
                :min(sim.chunk, len(first) - s0)])
        table = np.concatenate(parts)
    lams, jacs = [], []
    for start, idx in zip(range(0, n, sim.chunk), chunks):
        part = jax.tree_util.tree_map(lambda a: a[idx], scene_p)
        done = (jnp.zeros((len(idx), 5, static.n_zones, static.grid.n_nodes), jnp.float64) if table is None
                else jnp.asarray(table[group[idx]]))
        lam, jac = _LAM_JAC(static, names, arrays, part, sensor_p, ax, t, steps, only, done)
        keep = min(sim.chunk, n - start)
        lams.append(np.asarray(lam)[:keep])
        jacs.append(np.asarray(jac)[:keep])
        if progress is not None:
            progress(start + keep, n)
    return CountsJacobian(np.concatenate(lams), np.concatenate(jacs), ("x", "y") + tuple(f"log_{m}" for m in names),
                          sim.plan.fidelity)
