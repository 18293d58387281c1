"""Cramér–Rao bound on hidden-object localization from the fast simulator.

A capture's counts are independent Poisson variables whose means
``lam(theta)`` (zones x bins) are the fast simulator's expected counts; the
parameters ``theta`` are the object's displacement along two axes of the rig
(world x and y by default, z fixed) and nuisance parameters (photon scale,
the floor's ambient and dark rates, object albedo). The counts and their
derivatives come through the simulators' seam,
:func:`nlosplan.simulators.counts_and_jacobian` (re-exported here). The bound on the position error is
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

from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.simulators import FIDELITY_LEVELS, NUISANCE_PARAMETERS, Scene, counts_and_jacobian
from nlosplan.tasks.fisher import COND_MAX, analyse_fisher, poisson_fisher

__all__ = ["NUISANCE_PARAMETERS", "CRLBResult", "CRLBBatchResult", "analyse_fisher", "counts_and_jacobian",
           "fidelity_label", "localization_crlb", "localization_crlb_batch", "poisson_fisher"]


def fidelity_label(fid) -> str:
    """Name of a simulator fidelity level, or ``"custom"``."""
    return next((k for k, v in FIDELITY_LEVELS.items() if v == fid), "custom")


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
    lam, jac, names, fid = counts_and_jacobian(scenes, sensor, fidelity=fidelity, nuisance=nuisance, axes=axes,
                                               zones=zones, chunk=chunk, progress=progress)
    fisher = poisson_fisher(lam.reshape(len(scenes), -1), jac.reshape(len(scenes), -1, len(names)), repeats)
    per_scene = (time.perf_counter() - t0) / len(scenes)
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
