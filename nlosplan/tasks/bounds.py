"""Cramér–Rao bound on hidden-object localization from the fast simulator.

A capture's counts are independent Poisson variables whose means
``lam(theta)`` (zones x bins) are the fast simulator's expected counts; the
parameters ``theta`` are the object's displacement along two axes of the rig
(world x and y by default, z fixed) and nuisance parameters (photon scale,
ambient and dark rates, object albedo). The bound on the position error is
the position block of the inverse Fisher matrix, with the nuisance
parameters estimated; the bound with them known is reported beside it.

Examples
--------
>>> from nlosplan.sensor_models import preset
>>> from nlosplan.simulators import denali_scene
>>> res = localization_crlb(denali_scene("A", "8in", 19), preset("tmf8828-3x3-short"))  # doctest: +SKIP
>>> print(res.summary())  # doctest: +SKIP
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field

import numpy as np

from nlosplan._jax import jax, jnp
from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.transient import deposit_method
from nlosplan.simulators.fast.fidelity import FIDELITY_LEVELS, Fidelity
from nlosplan.simulators.fast.simulator import FastSimulator, to_jax
from nlosplan.simulators.fast.transport import object_nodes, scene_counts, sensor_terms
from nlosplan.simulators.scene import Scene
from nlosplan.tasks.fisher import COND_MAX, analyse_fisher, poisson_fisher

__all__ = ["NUISANCE_PARAMETERS", "CRLBResult", "CRLBBatchResult", "analyse_fisher", "counts_and_jacobian",
           "fidelity_label", "localization_crlb", "localization_crlb_batch", "poisson_fisher"]

#: Nuisance parameters, each in relative (log) units: d/dlog v = v d/dv at the nominal value v.
NUISANCE_PARAMETERS = ("photon_scale", "ambient", "dark", "albedo")
_SENSOR_FIELD = {"photon_scale": "photon_scale", "ambient": "ambient_rate_hz", "dark": "dark_rate_hz"}


def fidelity_label(fid: Fidelity) -> str:
    """Name of a simulator fidelity level, or ``"custom"``."""
    return next((k for k, v in FIDELITY_LEVELS.items() if v == fid), "custom")


# ----------------------------------------------------------------------------- model and Jacobian
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


def _check_nuisance(nuisance) -> tuple[str, ...]:
    names = (nuisance,) if isinstance(nuisance, str) else tuple(nuisance or ())
    bad = [n for n in names if n not in NUISANCE_PARAMETERS]
    if bad or len(set(names)) != len(names):
        raise UserError(f"nuisance={names!r}: each at most once from {', '.join(NUISANCE_PARAMETERS)}")
    return names


def _check_axes(axes) -> np.ndarray:
    a = np.eye(3)[:2] if axes is None else np.asarray(axes, dtype=np.float64)
    if a.shape != (2, 3) or not np.all(np.isfinite(a)):
        raise UserError(f"axes must be two world directions, shape (2, 3); got {np.shape(axes)}")
    norms = np.linalg.norm(a, axis=1)
    if np.any(norms < 1e-12):
        raise UserError("axes must be non-zero directions")
    a = a / norms[:, None]
    if abs(float(a[0] @ a[1])) > 1e-6:
        raise UserError("axes must be orthogonal (the RMS error sqrt(var_0 + var_1) is a Euclidean distance)")
    return a


def counts_and_jacobian(scenes, sensor: SensorConfig, *, fidelity="default", nuisance=("photon_scale",), axes=None,
                        zones=None, theta=None, chunk: int = 25, progress=None):
    """Expected counts and their derivatives with respect to position and nuisance parameters.

    Parameters
    ----------
    scenes : Scene or list of Scene
        Scenes of one rig (see :class:`~nlosplan.simulators.FastSimulator`).
    sensor : SensorConfig
    fidelity : str, dict or Fidelity
        Simulator quadrature level.
    nuisance : sequence of str
        From :data:`NUISANCE_PARAMETERS`.
    axes : array_like, shape (2, 3), optional
        Orthogonal world directions of the two position parameters (default world x and y).
    zones : list of (row, col), optional
        Only these zones.
    theta : array_like, shape (2 + len(nuisance),), optional
        Evaluate at this displacement (metres) and these log-changes (default 0: the scene as given).
    chunk : int
        Scenes per compiled call.
    progress : callable, optional
        ``progress(done, total)`` in scenes after each compiled call.

    Returns
    -------
    lam : ndarray, shape (N, Z, B)
        Expected counts (float64).
    jac : ndarray, shape (N, Z, B, P)
        ``d lam / d theta``: counts per metre for the positions, counts per unit log-change for the nuisances
        (central differences of ``POSITION_STEP_M`` and ``LOG_STEP``, see :func:`_lam_jac`).
    names : tuple of str
        Parameter names, e.g. ``("x", "y", "log_photon_scale")``.
    sim : FastSimulator
        The simulator used (its plan says what was computed).
    """
    names = _check_nuisance(nuisance)
    ax = jnp.asarray(_check_axes(axes))
    scenes = [scenes] if isinstance(scenes, Scene) else list(scenes)
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
    return np.concatenate(lams), np.concatenate(jacs), ("x", "y") + tuple(f"log_{m}" for m in names), sim


# ----------------------------------------------------------------------------- results
@dataclass(frozen=True, eq=False)
class CRLBResult:
    """Cramér–Rao bound on the position of a hidden object in one scene.

    Attributes
    ----------
    rmse_bound_m : float
        Lower bound on the RMS position error ``sqrt(var_0 + var_1)`` of any
        unbiased estimator, metres, with the nuisance parameters estimated;
        ``inf`` when the position is not identifiable (see ``reason``).
    std_m : ndarray, shape (2,)
        Per-axis bounds on the standard deviation, metres (``inf`` for an unidentifiable axis).
    covariance_m2 : ndarray, shape (2, 2)
        Position block of the inverse Fisher matrix, m^2.
    rmse_bound_known_m, std_known_m, covariance_known_m2
        The same with the nuisance parameters known (the position-only Fisher matrix).
    identifiable : bool
        Every parameter (position and nuisance) is identifiable.
    position_identifiable : bool
        The position bound is finite; a nuisance combination that is not
        identifiable but carries no position component leaves it so.
    reason : str
        Why not identifiable (empty when it is).
    null_directions : list of dict
        Parameter combinations without information.
    parameters : tuple of str
        Names of the Fisher matrix's rows: ``x``, ``y`` (metres along the axes), ``log_<nuisance>``.
    fisher : ndarray, shape (P, P)
        Fisher information of ``repeats`` captures, in those units.
    condition_number : float
        Of the equilibrated Fisher matrix (``D^-1/2 F D^-1/2``, ``D`` its diagonal).
    repeats : int
    seconds : float
        Wall time (a batch's time divided by its scenes).
    fidelity : str
        Simulator level (``"custom"`` for explicit knobs); ``knobs`` holds them.
    knobs : dict
    meta : dict
        The scene's labels.
    notes : tuple of str
        Nuisance parameters left out because they do not change the counts.
    """

    rmse_bound_m: float
    std_m: np.ndarray
    covariance_m2: np.ndarray
    rmse_bound_known_m: float
    std_known_m: np.ndarray
    covariance_known_m2: np.ndarray
    identifiable: bool
    position_identifiable: bool
    reason: str
    null_directions: list
    parameters: tuple
    fisher: np.ndarray
    condition_number: float
    repeats: int
    seconds: float
    fidelity: str
    knobs: dict
    meta: dict = field(default_factory=dict)
    notes: tuple = ()

    @property
    def loc_rmse_bound_m(self) -> float:
        """Bound on DENALI's pooled ``loc_rmse`` (metres): ``sqrt((var_0 + var_1) / 2)`` = ``rmse_bound_m / sqrt(2)``.

        ``rmse_bound_m`` bounds the 2-D RMS distance (the covariance's trace is a
        2-D mean square); ``loc_rmse`` averages over the x and y entries, so the
        trace is halved under the root before the two are compared.
        """
        return self.rmse_bound_m / math.sqrt(2.0)

    @property
    def nuisance_price(self) -> float:
        """``rmse_bound_m / rmse_bound_known_m`` (>= 1): the cost of estimating the nuisances."""
        if not (math.isfinite(self.rmse_bound_m) and self.rmse_bound_known_m > 0):
            return math.inf
        return self.rmse_bound_m / self.rmse_bound_known_m

    def summary(self) -> str:
        """One line; an unidentifiable position says so instead of printing a number."""
        def mm(v):
            return f"{1e3 * v:.3g} mm" if math.isfinite(v) else "NOT IDENTIFIABLE"

        nuisance = ", ".join(n.removeprefix("log_") for n in self.parameters[2:]) or "none"
        s = (f"CRLB RMS position error >= {mm(self.rmse_bound_m)} (nuisance {nuisance}"
             f" estimated; known: {mm(self.rmse_bound_known_m)}), {self.repeats} capture(s), "
             f"fidelity {self.fidelity}, {self.seconds:.3g} s")
        return s + (f" [{self.reason}]" if self.reason else "")

    def to_dict(self) -> dict:
        """JSON-friendly (``inf`` stays a float; arrays become lists)."""
        out = {k: getattr(self, k) for k in self.__dataclass_fields__}
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in out.items()}


@dataclass(frozen=True, eq=False)
class CRLBBatchResult:
    """Bounds over many scenes (e.g. the 100 DENALI positions).

    Attributes
    ----------
    results : list of CRLBResult
    rms_bound_m : float
        ``sqrt(mean_s rmse_bound_m(s)^2)``: the bound on a model's 2-D RMS distance
        error over these scenes (``inf`` if any scene's position is not
        identifiable); :attr:`loc_rmse_bound_m` bounds DENALI's pooled RMSE.
    rms_bound_known_m : float
        The same with the nuisance parameters known.
    unidentifiable : list of int
        Indices of scenes whose position is not identifiable.
    seconds : float
        Wall time of the whole batch (plan, compilation, Jacobians, inversions).
    fidelity : str
    knobs : dict
    """

    results: list
    rms_bound_m: float
    rms_bound_known_m: float
    unidentifiable: list
    seconds: float
    fidelity: str
    knobs: dict

    @property
    def loc_rmse_bound_m(self) -> float:
        """Bound on DENALI's pooled ``loc_rmse`` over these scenes: ``rms_bound_m / sqrt(2)`` (see :class:`CRLBResult`)."""
        return self.rms_bound_m / math.sqrt(2.0)

    def summary(self) -> str:
        """One line."""
        bad = f"NOT IDENTIFIABLE in {len(self.unidentifiable)} scene(s)"

        def mm(v):
            return f"{1e3 * v:.3g} mm" if math.isfinite(v) else bad

        return (f"CRLB RMS over {len(self.results)} scenes >= {mm(self.rms_bound_m)} (nuisance known: "
                f"{mm(self.rms_bound_known_m)}), fidelity {self.fidelity}, {self.seconds:.3g} s")


# ----------------------------------------------------------------------------- front ends
def _rmse(cov) -> tuple[float, np.ndarray]:
    var = np.diag(cov)
    return float(math.sqrt(var.sum())) if np.all(np.isfinite(var)) else math.inf, np.sqrt(var)


def localization_crlb_batch(scenes, sensor: SensorConfig, *, fidelity="default", repeats: int = 1,
                            nuisance=("photon_scale",), axes=None, zones=None, cond_max: float = COND_MAX,
                            chunk: int = 25, progress=None) -> CRLBBatchResult:
    """Cramér–Rao bounds on localization for many scenes with one compiled simulator.

    Parameters
    ----------
    scenes : list of Scene
        Scenes of one rig (e.g. ``[denali_scene("A", "8in", p) for p in range(100)]``).
    sensor : SensorConfig
    fidelity : str, dict or Fidelity
        Simulator quadrature level (the evaluator's fidelity knob).
    repeats : int
        Independent captures per scene.
    nuisance : sequence of str
        Estimated alongside the position, from :data:`NUISANCE_PARAMETERS`.
        A nuisance that does not change a scene's counts at all (``ambient``
        with lights off, ``dark`` at a zero rate) is left out for that scene
        with a note.
    axes : array_like, shape (2, 3), optional
        Orthogonal world directions of the position (default world x, y).
    zones : list of (row, col), optional
        Only these zones.
    cond_max : float
        Condition-number threshold of the equilibrated Fisher matrix.
    chunk : int
        Scenes per compiled call.
    progress : callable, optional
        ``progress(done, total)`` in scenes as the Jacobians are computed.

    Returns
    -------
    CRLBBatchResult

    Notes
    -----
    ``I = repeats * J^T diag(1/lam) J`` with ``J = d lam / d theta`` from
    the simulator in float64 (:func:`counts_and_jacobian`). Pile-up and
    the 24-bit clip enter through ``lam`` (a clipped bin has zero
    derivative: no information), but the counts are treated as Poisson.
    The bound holds for unbiased estimators; a model that knows the 100
    DENALI positions (a discrete prior) may beat it.
    """
    t0 = time.perf_counter()
    scenes = [scenes] if isinstance(scenes, Scene) else list(scenes)
    if not scenes:
        raise UserError("give at least one scene")
    lam, jac, names, sim = counts_and_jacobian(scenes, sensor, fidelity=fidelity, nuisance=nuisance, axes=axes,
                                               zones=zones, chunk=chunk, progress=progress)
    fisher = poisson_fisher(lam.reshape(len(scenes), -1), jac.reshape(len(scenes), -1, len(names)), repeats)
    per_scene = (time.perf_counter() - t0) / len(scenes)
    fid = sim.plan.fidelity
    results = []
    for i, scene in enumerate(scenes):
        t1 = time.perf_counter()
        zero = ~np.any(jac[i] != 0, axis=(0, 1))
        kept = [k for k in range(len(names)) if k < 2 or not zero[k]]
        notes = tuple(f"{names[k].removeprefix('log_')} left out: it does not change the counts"
                      + (" (lights off)" if names[k] == "log_ambient" and not scene.lights_on else "")
                      for k in range(2, len(names)) if zero[k])
        f = fisher[i][np.ix_(kept, kept)]
        kept_names = tuple(names[k] for k in kept)
        est = analyse_fisher(f, kept_names, cond_max=cond_max)
        known = analyse_fisher(f[:2, :2], kept_names[:2], cond_max=cond_max)
        rmse, std = _rmse(est["covariance"])
        rmse_k, std_k = _rmse(known["covariance"])
        if not est["position_identifiable"]:
            rmse = math.inf
        results.append(CRLBResult(
            rmse_bound_m=rmse, std_m=std, covariance_m2=est["covariance"], rmse_bound_known_m=rmse_k,
            std_known_m=std_k, covariance_known_m2=known["covariance"], identifiable=est["identifiable"],
            position_identifiable=est["position_identifiable"], reason=est["reason"],
            null_directions=est["null_directions"], parameters=kept_names, fisher=f,
            condition_number=est["condition_number"], repeats=int(repeats),
            seconds=per_scene + time.perf_counter() - t1, fidelity=fidelity_label(fid), knobs=fid.to_dict(),
            meta=dict(scene.meta), notes=notes))
    bad = [i for i, r in enumerate(results) if not math.isfinite(r.rmse_bound_m)]

    def rms(values):
        v = np.asarray(values)
        return float(np.sqrt(np.mean(v ** 2))) if np.all(np.isfinite(v)) else math.inf

    return CRLBBatchResult(results=results, rms_bound_m=rms([r.rmse_bound_m for r in results]),
                           rms_bound_known_m=rms([r.rmse_bound_known_m for r in results]), unidentifiable=bad,
                           seconds=time.perf_counter() - t0, fidelity=fidelity_label(fid), knobs=fid.to_dict())


def localization_crlb(scene: Scene, sensor: SensorConfig, *, fidelity="default", repeats: int = 1,
                      nuisance=("photon_scale",), axes=None, zones=None, cond_max: float = COND_MAX) -> CRLBResult:
    """Cramér–Rao bound on the position of the hidden object in one scene.

    Parameters as :func:`localization_crlb_batch`.

    Returns
    -------
    CRLBResult
        ``rmse_bound_m`` (nuisance estimated) and ``rmse_bound_known_m``;
        an unidentifiable position gives ``inf`` with ``reason``, never a huge finite number.

    Examples
    --------
    >>> from nlosplan.sensor_models import preset
    >>> from nlosplan.simulators import denali_scene
    >>> r = localization_crlb(denali_scene("A", "8in", 19), preset("tmf8828-3x3-short"), fidelity="draft")
    >>> r.position_identifiable and r.rmse_bound_m >= r.rmse_bound_known_m
    True
    """
    if not isinstance(scene, Scene):
        raise UserError(f"scene must be a Scene (e.g. denali_scene(...)), not {type(scene).__name__}")
    batch = localization_crlb_batch([scene], sensor, fidelity=fidelity, repeats=repeats, nuisance=nuisance,
                                    axes=axes, zones=zones, cond_max=cond_max, chunk=1)
    return dataclasses.replace(batch.results[0], seconds=batch.seconds)
