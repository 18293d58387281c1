"""Ideal-observer classification of hidden-object shape and size (Monte Carlo).

The ideal observer knows the forward model exactly: for a capture ``y``
(counts, zones x bins) it picks the class ``c`` with the largest Poisson
log-likelihood ``sum_k y_k log lam_k - lam_k``, where ``lam`` are the fast
simulator's expected counts. Its accuracy bounds what any classifier
trained on data from the same model can reach. Positions (and, for the size
task, the object's shape) that the observer does not know are nuisances:
it marginalises over them with a uniform prior (Bayes-optimal, the default)
or maximises over them (generalised likelihood ratio).

Examples
--------
>>> from nlosplan.sensor_models import preset
>>> res = ideal_observer("shape", preset("tmf8828-3x3-short"), draws=20)  # doctest: +SKIP
>>> print(res.summary())  # doctest: +SKIP
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np
from scipy import stats

from nlosplan.errors import UserError
from nlosplan.sensor_models.config import SensorConfig
from nlosplan.sensor_models.noise import CaptureNoise
from nlosplan.denali import DENALI_OBJECTS, N_POSITIONS, SIZES
from nlosplan.simulators import denali_scene, expected_batch
from nlosplan.tasks.bounds import fidelity_label

__all__ = ["TASKS", "RULES", "IdealObserverResult", "binomial_interval", "ideal_observer", "observer_accuracy"]

TASKS = ("shape", "size")
RULES = ("marginal", "max")
#: Log-likelihood differences below this (nats) are ties, broken at random.
TIE_NATS = 1e-6
#: Floor on expected counts inside the logarithm: a bin that a hypothesis says is empty but holds counts makes
#: that hypothesis (almost) impossible without an infinite log-likelihood.
LAM_FLOOR = 1e-30


def binomial_interval(successes: int, n: int, confidence: float = 0.95, method: str = "wilson") -> tuple[float, float]:
    """Confidence interval of a binomial proportion.

    Parameters
    ----------
    successes, n : int
    confidence : float
        Two-sided level in (0, 1).
    method : {"wilson", "clopper-pearson"}
        Wilson score interval, or the exact (conservative) Clopper–Pearson one.

    Returns
    -------
    (low, high) : tuple of float
        In [0, 1]; ``(0, 1)`` when ``n == 0``.
    """
    if not 0 < confidence < 1:
        raise UserError(f"confidence={confidence} must be in (0, 1)")
    if n <= 0:
        return 0.0, 1.0
    k, alpha = int(successes), 1.0 - confidence
    if method == "clopper-pearson":
        low = 0.0 if k == 0 else float(stats.beta.ppf(alpha / 2, k, n - k + 1))
        high = 1.0 if k == n else float(stats.beta.ppf(1 - alpha / 2, k + 1, n - k))
        return low, high
    if method != "wilson":
        raise UserError(f"unknown interval method {method!r}; allowed: wilson, clopper-pearson")
    z = float(stats.norm.ppf(1 - alpha / 2))
    p = k / n
    centre = (p + z * z / (2 * n)) / (1 + z * z / n)
    half = z / (1 + z * z / n) * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n))
    return max(0.0, centre - half), min(1.0, centre + half)


@dataclass(frozen=True, eq=False)
class IdealObserverResult:
    """Monte-Carlo accuracy of the ideal observer.

    Attributes
    ----------
    task : str
    classes : tuple of str
    accuracy : float
        Fraction of correctly classified draws.
    ci : (float, float)
        Confidence interval of the accuracy (``ci_method`` at ``confidence``).
    confusion : ndarray of int, shape (C, C)
        Rows: true class, columns: decision.
    per_class_accuracy : ndarray, shape (C,)
    draws : int
        Noisy captures per class (the Monte-Carlo fidelity knob); ``n = draws * C``.
    n : int
    position_known : bool
    rule : {"marginal", "max"}
    seconds : float
        Wall time in all; ``seconds_simulation`` of it for the expected counts.
    seconds_simulation : float
    fidelity : str
        Simulator level (``knobs`` holds its knobs).
    knobs : dict
    seed : int or None
    confidence : float
    ci_method : str
    meta : dict
        Sensor, lights, sizes, objects, positions and the like.
    """

    task: str
    classes: tuple
    accuracy: float
    ci: tuple
    confusion: np.ndarray
    per_class_accuracy: np.ndarray
    draws: int
    n: int
    position_known: bool
    rule: str
    seconds: float
    seconds_simulation: float
    fidelity: str
    knobs: dict
    seed: int | None
    confidence: float
    ci_method: str
    meta: dict = field(default_factory=dict)

    @property
    def error_rate(self) -> float:
        """``1 - accuracy``."""
        return 1.0 - self.accuracy

    @property
    def chance(self) -> float:
        """Accuracy of guessing, ``1 / C``."""
        return 1.0 / len(self.classes)

    def summary(self) -> str:
        """One line."""
        lo, hi = self.ci
        pos = "known" if self.position_known else f"unknown ({self.rule})"
        return (f"ideal observer, {self.task} ({len(self.classes)} classes, position {pos}): accuracy "
                f"{self.accuracy:.3f} [{lo:.3f}, {hi:.3f}] ({100 * self.confidence:.0f} % {self.ci_method}), "
                f"chance {self.chance:.3f}, {self.draws} draws/class, fidelity {self.fidelity}, {self.seconds:.3g} s")

    def to_dict(self) -> dict:
        """JSON-friendly."""
        out = {k: getattr(self, k) for k in self.__dataclass_fields__}
        return {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in out.items()}


def _draw_plan(rng, class_of, n_pos, draws):
    """Stratified truths: per class, hypotheses and positions cycle through shuffled orders. (n,) each."""
    hyp, pos = [], []
    for c in range(int(class_of.max()) + 1):
        members = np.flatnonzero(class_of == c)
        reps_h = -(-draws // members.size)
        reps_p = -(-draws // n_pos)
        hyp.append(np.concatenate([rng.permutation(members) for _ in range(reps_h)])[:draws])
        pos.append(np.concatenate([rng.permutation(n_pos) for _ in range(reps_p)])[:draws])
    return np.concatenate(hyp), np.concatenate(pos)


def observer_accuracy(means, class_of, *, draws: int, seed=0, position_known: bool = False, rule: str = "marginal",
                      same_group=None, noise: bool = True, capture_noise: CaptureNoise | None = None,
                      confidence: float = 0.95,
                      ci_method: str = "wilson", class_names=None, chunk_bytes: int = 1 << 27,
                      precision: str = "float32", stop_at=None, looks: int = 4, stop_confidence: float = 0.999,
                      progress=None) -> dict:
    """Monte-Carlo accuracy of the ideal observer on precomputed expected counts.

    Parameters
    ----------
    means : array_like, shape (H, P, D)
        Expected counts of hypothesis ``h`` (e.g. an object at a size) at
        position ``p``, flattened over zones and bins.
    class_of : array_like of int, shape (H,)
        Class of each hypothesis (0..C-1); hypotheses of one class are a
        nuisance (uniform prior within the class).
    draws : int
        Noisy captures per class; truths cycle through the class's
        hypotheses and the positions in shuffled orders.
    seed : int or numpy.random.Generator
        Randomness of the truths, the Poisson counts and tie-breaking.
    position_known : bool
        The observer is told the true position (conditional observer).
    rule : {"marginal", "max"}
        Unknown nuisances: log-sum-exp with a uniform prior (Bayes-optimal) or maximum.
    same_group : array_like of int, shape (H,), optional
        The observer is told the truth's group (e.g. its shape in the size
        task) and considers only hypotheses of that group.
    noise : bool
        Noisy captures (True) or the expectation itself (``y = lam``).
    capture_noise : CaptureNoise, optional
        How the captures are drawn (:meth:`CaptureNoise.of(sensor) <nlosplan.sensor_models.noise.CaptureNoise.of>`:
        Poisson, clipped at the sensor's 24-bit maximum); default Poisson without a clip.
    confidence, ci_method
        See :func:`binomial_interval`.
    class_names : sequence of str, optional
    chunk_bytes : int
        Memory for one chunk's (draws x H*P) log-likelihood block and its (draws x D) noisy captures.
    precision : {"float32", "float64"}
        Of the matrix product (the rest is float64). float32: the captures and the log-expectations are
        centred first, so its error is at most 5e-4 nats on the main job's 8x8 cube (3,498 bins), against
        log-likelihood gaps of order 1; ×1.5 faster there, decisions equal to float64's (a difference
        would need a gap under 5e-4 nats, a likelihood ratio within 0.05 % of 1). Identical hypotheses
        get identical log-likelihoods in either precision, so their ties stay ties.
    stop_at : sequence of float, optional
        Accuracies that matter (a requirement's threshold): the captures are drawn in ``looks`` equal,
        stratified rounds, and the Monte Carlo stops after a round once the ``stop_confidence`` interval
        (``ci_method``) of the accuracy so far lies wholly above or below every one of them, so a design
        far from every threshold costs a round, not ``draws``. None: all ``draws`` (the default).
    looks : int
        Rounds of ``stop_at`` (each ``ceil(draws / looks)`` captures per class).
    stop_confidence : float
        Level of the stopping interval, stricter than ``confidence`` because it is looked at up to
        ``looks`` times: at 0.999 and 4 looks the chance that any look's interval misses the true accuracy
        (the only way to stop with a threshold on the wrong side of it) is at most 0.4 % (a union bound).
    progress : callable, optional
        ``progress(done, total)`` in noisy captures after each chunk.

    Returns
    -------
    dict
        ``accuracy``, ``ci``, ``confusion`` (C, C), ``per_class_accuracy``
        (C,), ``n`` (captures drawn), ``draws`` (per class drawn: ``draws`` unless
        stopped early), ``stopped_early``, ``truth`` and ``decision`` (n,) class indices.

    Notes
    -----
    Log-likelihoods of all hypotheses and positions are one matrix product
    ``Y @ log(Lam)^T - sum(Lam)``, with ``log Lam`` centred over hypotheses (a
    per-capture constant) so the large direct peak, the same for all, does not
    eat the precision; in float32 the captures are centred on the mean
    expectation too (``(Y - mu) @ L^T + mu @ L^T``, the second term in float64),
    so the product's terms are Poisson fluctuations times log-ratios. Bins with the
    same expectation under every hypothesis and position are left out (neither drawn nor multiplied:
    they add the same to every log-likelihood). Ties within :data:`TIE_NATS` are
    broken uniformly at random.
    """
    lam = np.asarray(means, dtype=np.float64)
    class_of = np.asarray(class_of, dtype=np.int64)
    if lam.ndim != 3 or class_of.shape != (lam.shape[0],):
        raise UserError(f"means must be (H, P, D) and class_of (H,); got {lam.shape} and {class_of.shape}")
    if not np.all(np.isfinite(lam)) or np.any(lam < 0):
        raise UserError("expected counts must be finite and >= 0")
    if rule not in RULES:
        raise UserError(f"unknown rule {rule!r}; allowed: {', '.join(RULES)}")
    if int(draws) < 1:
        raise UserError(f"draws={draws} must be >= 1")
    if precision not in ("float32", "float64"):
        raise UserError(f"unknown precision {precision!r}; allowed: float32, float64")
    if int(looks) < 1:
        raise UserError(f"looks={looks} must be >= 1")
    if not 0 < stop_confidence < 1:
        raise UserError(f"stop_confidence={stop_confidence} must be in (0, 1)")
    stops = () if stop_at is None else tuple(float(v) for v in np.atleast_1d(stop_at))
    if not all(math.isfinite(v) for v in stops):
        raise UserError(f"stop_at must be finite accuracies; got {stop_at!r}")
    n_h, n_p, _ = lam.shape
    n_c = int(class_of.max()) + 1
    if set(np.unique(class_of)) != set(range(n_c)):
        raise UserError("class_of must use every class index 0..C-1")
    group = None if same_group is None else np.asarray(same_group)
    rng = seed if isinstance(seed, np.random.Generator) else np.random.default_rng(seed)
    draw = (capture_noise or CaptureNoise()).draw
    truth_h, truth_p = _draw_plan(rng, class_of, n_p, int(draws))
    starts = [0]  # where each round begins in the draw order
    if stops:  # stratified rounds: round k holds the k-th slice of every class's draws
        per = -(-int(draws) // int(looks))
        order = np.arange(truth_h.size).reshape(n_c, int(draws))
        parts = [order[:, k:k + per].reshape(-1) for k in range(0, int(draws), per)]
        perm = np.concatenate(parts)
        truth_h, truth_p = truth_h[perm], truth_p[perm]
        starts = [0, *np.cumsum([p.size for p in parts])[:-1].tolist()]
    flat = lam.reshape(n_h * n_p, -1)
    total = flat.sum(axis=1)
    total -= total.mean()
    # a bin whose expectation is the same under every hypothesis and position (before the earliest object light:
    # the floor and the direct return; 57 % of the main job's 8x8 bins) adds the same log-likelihood to every
    # hypothesis: it cannot change a decision, so it is neither drawn nor multiplied (the logarithm's spread, taken
    # only where the expectation itself differs: rounding-level differences the logarithm does not keep stay out)
    informative = np.flatnonzero(np.ptp(np.maximum(flat, LAM_FLOOR), axis=0) > 0)
    lam_obs = flat[:, informative]  # one copy of the informative columns (an 8x8 cube's: 0.45 s each)
    log_lam = np.log(np.maximum(lam_obs, LAM_FLOOR))
    kept = np.ptp(log_lam, axis=0) > 0
    if not kept.all():
        informative, log_lam, lam_obs = informative[kept], log_lam[:, kept], lam_obs[:, kept]
    if informative.size == 0:
        informative = np.arange(1)
        lam_obs = flat[:, :1]
        log_lam = np.log(np.maximum(lam_obs, LAM_FLOOR))
    log_lam -= log_lam.mean(axis=0)
    lam_obs = lam_obs.reshape(n_h, n_p, -1)
    if precision == "float32":
        centre = lam_obs.reshape(n_h * n_p, -1).mean(axis=0)
        total = total - log_lam @ centre  # (Y - mu) @ L^T + mu @ L^T - sum(Lam): the constant part in float64
        log_lam = log_lam.astype(np.float32)
    members = [np.flatnonzero(class_of == c) for c in range(n_c)]
    decision = np.full(truth_h.size, -1, np.int64)
    # a chunk's (draws x H*P) log-likelihoods and its (draws x D) captures both fit in chunk_bytes
    step = max(1, int(chunk_bytes // (8 * max(n_h * n_p, log_lam.shape[1]))))
    ends = [*starts[1:], truth_h.size]
    chunks = [(i, min(i + step, end)) for begin, end in zip(starts, ends) for i in range(begin, end, step)]
    done = 0
    for start, stop in chunks:
        if start in starts[1:]:  # a round ends: stop once its interval is clear of every threshold
            lo, hi = binomial_interval(int(np.sum(class_of[truth_h[:start]] == decision[:start])), start,
                                       stop_confidence, ci_method)
            if all(v < lo or v > hi for v in stops):
                break
        th, tp = truth_h[start:stop], truth_p[start:stop]
        y = lam_obs[th, tp]
        if noise:
            y = draw(rng, y).astype(np.float64)
        if precision == "float32":
            ll = (((y - centre).astype(np.float32) @ log_lam.T) - total).reshape(-1, n_h, n_p)  # float64 (m, H, P)
        else:
            ll = (y @ log_lam.T - total).reshape(-1, n_h, n_p)  # (m, H, P)
        if position_known:
            ll = np.where(np.arange(n_p)[None, None, :] == tp[:, None, None], ll, -np.inf)
        if group is not None:
            ll = np.where(group[None, :, None] == group[th][:, None, None], ll, -np.inf)
        score = np.empty((th.size, n_c))
        for c, idx in enumerate(members):
            block = ll[:, idx].reshape(th.size, -1)
            top = block.max(axis=1)
            if rule == "max":
                score[:, c] = top
            else:  # uniform prior over the class's hypotheses and the positions the observer considers
                ok = np.isfinite(top)
                safe = np.where(ok, top, 0.0)
                n_cons = np.isfinite(block).sum(axis=1)
                lse = safe + np.log(np.exp(block - safe[:, None]).sum(axis=1))
                score[:, c] = np.where(ok, lse - np.log(np.maximum(n_cons, 1)), -np.inf)
        best = score.max(axis=1, keepdims=True)
        tied = score >= best - TIE_NATS
        decision[start:stop] = np.argmax(np.where(tied, rng.random(score.shape), -1.0), axis=1)
        done = stop
        if progress is not None:
            progress(stop, truth_h.size)
    truth, decision = class_of[truth_h[:done]], decision[:done]
    confusion = np.zeros((n_c, n_c), np.int64)
    np.add.at(confusion, (truth, decision), 1)
    correct = int(np.trace(confusion))
    names = tuple(class_names) if class_names is not None else tuple(str(c) for c in range(n_c))
    return {"accuracy": correct / truth.size, "ci": binomial_interval(correct, truth.size, confidence, ci_method),
            "confusion": confusion, "per_class_accuracy": np.diag(confusion) / confusion.sum(axis=1),
            "n": int(truth.size), "draws": int(truth.size // n_c), "stopped_early": bool(done < truth_h.size),
            "truth": truth, "decision": decision, "classes": names}


def _positions(positions) -> list[int]:
    if positions is None:
        return list(range(N_POSITIONS))
    if isinstance(positions, (int, np.integer)):
        return [int(positions)]
    out = [int(p) for p in positions]
    if not out or len(set(out)) != len(out):
        raise UserError("positions must be distinct DENALI position indices (0..99)")
    return out


def ideal_observer(task: str, sensor: SensorConfig, *, objects=None, size: str = "8in", positions=None,
                   lights: str = "off", position_known: bool = False, rule: str = "marginal",
                   shape_known: bool = False, draws: int = 100, seed: int = 0, fidelity="default",
                   confidence: float = 0.95, ci_method: str = "wilson", noise: bool = True,
                   scene_kw: dict | None = None, progress=None) -> IdealObserverResult:
    """Ideal-observer accuracy for DENALI shape or size classification.

    Parameters
    ----------
    task : {"shape", "size"}
        ``shape``: which of ``objects`` (at ``size``). ``size``: 4 in or 8 in,
        with the object's shape among ``objects`` unknown to the observer
        (a nuisance like the position) unless ``shape_known``.
    sensor : SensorConfig
    objects : sequence of str, optional
        DENALI object names (default all 30).
    size : {"4in", "8in"}
        Object size of the shape task.
    positions : sequence of int, optional
        Gantry positions that truths are drawn from and, with the position
        unknown, that the observer considers (default all 100).
    lights : {"off", "on"}
    position_known : bool
        Conditional observer: told the true position.
    rule : {"marginal", "max"}
        How an unknown position (and shape) is handled: marginalised with a
        uniform prior (default; Bayes-optimal when truths are drawn uniformly
        from ``positions``, as here) or maximised.
    shape_known : bool
        Size task only: the observer is told the object's shape.
    draws : int
        Noisy captures per class (the Monte-Carlo fidelity knob).
    seed : int
    fidelity : str, dict or Fidelity
        Simulator quadrature level of the expected counts.
    confidence, ci_method
        See :func:`binomial_interval`.
    noise : bool
        Poisson captures (True) or noise-free ``y = lam`` (a check).
    scene_kw : dict, optional
        More arguments of :func:`~nlosplan.simulators.denali_scene` (e.g. ``mount=True``).
    progress : callable, optional
        ``progress(stage, done, total)``: ``"simulation"`` (scenes, once done) then ``"draws"`` (noisy captures).

    Returns
    -------
    IdealObserverResult

    Notes
    -----
    The expected counts of every (object, size, position) come from one
    batch of the fast backend in float64 (:func:`~nlosplan.simulators.expected_batch`); the
    classification is :func:`observer_accuracy`.
    """
    t0 = time.perf_counter()
    if task not in TASKS:
        raise UserError(f"unknown task {task!r}; allowed: {', '.join(TASKS)}")
    objs = list(DENALI_OBJECTS if objects is None else ([objects] if isinstance(objects, str) else objects))
    if not objs or len(set(objs)) != len(objs):
        raise UserError("objects must be distinct DENALI object names")
    if task == "shape":
        if size not in SIZES:
            raise UserError(f"unknown size {size!r}; allowed: {', '.join(SIZES)}")
        if len(objs) < 2:
            raise UserError("the shape task needs at least two objects")
        hyps = [(o, size) for o in objs]
        class_of, class_names, group = np.arange(len(objs)), tuple(objs), None
    else:
        hyps = [(o, s) for s in SIZES for o in objs]
        class_of = np.repeat(np.arange(len(SIZES)), len(objs))
        class_names = SIZES
        group = np.tile(np.arange(len(objs)), len(SIZES)) if shape_known else None
    pos = _positions(positions)
    kw = dict(scene_kw or {})
    scenes = [denali_scene(o, s, p, lights, **kw) for o, s in hyps for p in pos]
    batch = expected_batch(scenes, sensor, fidelity=fidelity, dtype="float64")
    means = np.asarray(batch.expected).reshape(len(hyps), len(pos), -1)
    t_sim = time.perf_counter() - t0
    if progress is not None:
        progress("simulation", len(scenes), len(scenes))
    out = observer_accuracy(means, class_of, draws=draws, seed=seed, position_known=position_known, rule=rule,
                            same_group=group, noise=noise, capture_noise=CaptureNoise.of(sensor),
                            confidence=confidence, ci_method=ci_method, class_names=class_names,
                            progress=None if progress is None else (lambda d, t: progress("draws", d, t)))
    fid = batch.fidelity
    meta = {"sensor": sensor.name, "lights": lights, "size": size if task == "shape" else list(SIZES),
            "objects": objs, "positions": pos, "shape_known": bool(shape_known) if task == "size" else None,
            "noise": bool(noise), "zones": f"{sensor.zones_rows}x{sensor.zones_cols}", "n_bins": sensor.n_bins}
    return IdealObserverResult(
        task=task, classes=class_names, accuracy=out["accuracy"], ci=out["ci"], confusion=out["confusion"],
        per_class_accuracy=out["per_class_accuracy"], draws=int(draws), n=out["n"],
        position_known=bool(position_known), rule=rule, seconds=time.perf_counter() - t0, seconds_simulation=t_sim,
        fidelity=fidelity_label(fid), knobs=fid.to_dict(), seed=seed, confidence=confidence, ci_method=ci_method,
        meta=meta)
