"""Three-valued verdicts and the intervals they rest on.

A requirement is judged on a metric's 95 % interval ``[lo, hi]``:

- **met**: the pessimistic end meets it (``hi <= threshold`` for the
  localization RMSE, ``lo >= threshold`` for an accuracy);
- **not met**: even the optimistic end fails it;
- **undecided**: the interval straddles the threshold.

Intervals resample what a re-run would change. One *run* of a design is one
evaluation at one seed: new Poisson noise on the captures, a new random
train/test split, a new training seed (:func:`~nlosplan.planner.design.evaluators.evaluate`).
A design evaluated at ``k`` seeds gets the mean of the ``k`` runs and the
interval of that mean, built on the *score* scale (log RMSE, logit
accuracy: :func:`metric_to_score`), where the run-to-run spread is about the same for every
design of a task: the spread of one run is the pooled between-seed variance
of every design of the task evaluated at two seeds or more (``pooled``), or
the run's own bootstrap over its test scenes where that is larger (one run
cannot vary less than its test set does). The 95 % quantile is Student's t
with the pooled degrees of freedom (the normal one when only the bootstraps
are known). So a design trained at one seed still has an interval that
covers a re-run, and more seeds narrow it as ``1 / sqrt(k)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from enum import StrEnum

import numpy as np

__all__ = ["Verdict", "MET", "NOT_MET", "UNDECIDED", "VERDICTS", "VERDICT_DEFINITIONS", "Z95", "Spread", "Estimate",
           "verdict", "metric_to_score", "score_to_metric", "pooled_spread", "within_sd", "seed_interval",
           "rank_correlation"]


class Verdict(StrEnum):
    """A requirement's three-valued verdict; a member is its text (``Verdict.NOT_MET == "not met"``)."""

    MET = "met"
    NOT_MET = "not met"
    UNDECIDED = "undecided"


MET, NOT_MET, UNDECIDED = Verdict.MET, Verdict.NOT_MET, Verdict.UNDECIDED
VERDICTS = tuple(Verdict)
#: What each verdict means (the report's and the JSON's ``metric_definitions``).
VERDICT_DEFINITIONS = {
    MET: "the pessimistic end of the 95 % interval meets the requirement",
    NOT_MET: "even the optimistic end of the 95 % interval fails it",
    UNDECIDED: "the 95 % interval straddles the threshold (more seeds may decide it)",
}
#: The normal 97.5 % quantile: the 95 % interval's half-width in standard errors when no pooled spread is known.
Z95 = 1.959963984540054


def verdict(req, lo: float, hi: float) -> Verdict:
    """``met``, ``not met`` or ``undecided`` for an interval ``[lo, hi]`` (NaN: undecided)."""
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return UNDECIDED
    pessimistic, optimistic = (hi, lo) if req.smaller_is_better else (lo, hi)
    if req.met(pessimistic):
        return MET
    if not req.met(optimistic):
        return NOT_MET
    return UNDECIDED


def metric_to_score(req, v: float) -> float:
    """The scale intervals and gaps work on: log RMSE (m), or logit accuracy (clipped to [0.001, 0.999])."""
    if req.smaller_is_better:
        return math.log(max(v, 1e-9))
    p = min(max(v, 1e-3), 1 - 1e-3)
    return math.log(p / (1 - p))


def score_to_metric(req, z: float) -> float:
    """Inverse of :func:`metric_to_score`."""
    if req.smaller_is_better:
        return math.exp(z)
    return 1.0 / (1.0 + math.exp(-z))


@dataclass(frozen=True)
class Spread:
    """Run-to-run variance of one task's metric on the score scale.

    Attributes
    ----------
    var : float
        Pooled between-seed variance (NaN when no design has two seeds).
    dof : int
        Its degrees of freedom (sum over designs of seeds - 1).
    designs : int
        Designs it pools.
    """

    var: float = math.nan
    dof: int = 0
    designs: int = 0

    @property
    def sd(self) -> float:
        return math.sqrt(self.var) if math.isfinite(self.var) else math.nan


def pooled_spread(req, groups) -> Spread:
    """Pooled between-seed variance over designs.

    Parameters
    ----------
    req : Requirement
    groups : iterable of sequences of float
        Metric values of each design's seeds (designs with one seed add nothing).
    """
    ss, dof, n = 0.0, 0, 0
    for vals in groups:
        s = np.array([metric_to_score(req, v) for v in vals if math.isfinite(v)])
        if len(s) < 2:
            continue
        ss += float(((s - s.mean()) ** 2).sum())
        dof += len(s) - 1
        n += 1
    return Spread(ss / dof if dof else math.nan, dof, n)


def within_sd(req, run) -> float:
    """A run's own standard error on the score scale, from its bootstrap interval ``run.lo``, ``run.hi`` (NaN if none)."""
    lo, hi = run.lo, run.hi
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return math.nan
    return abs(metric_to_score(req, hi) - metric_to_score(req, lo)) / (2 * Z95)


@dataclass(frozen=True)
class Estimate:
    """A design's metric over its seed runs: the mean, the 95 % interval of that mean and its verdict.

    Attributes
    ----------
    value : float
        Mean of the runs (m for ``loc_rmse``, a fraction for accuracies).
    lo, hi : float
        The 95 % interval of the mean (same unit).
    verdict : Verdict
        Of ``[lo, hi]`` against the requirement.
    seeds : int
        Runs averaged.
    seconds : float
        Their run time, s (summed).
    sd_run : float
        One run's standard deviation on the score scale.
    quantile : float
        The quantile the half-width used (Student's t or :data:`Z95`).
    """

    value: float
    lo: float
    hi: float
    verdict: Verdict
    seeds: int
    seconds: float
    sd_run: float
    quantile: float

    def optimistic(self, req) -> float:
        """The end of the interval on the requirement's good side (``lo`` for an error, ``hi`` for an accuracy)."""
        return self.lo if req.smaller_is_better else self.hi

    def pessimistic(self, req) -> float:
        """The other end: ``met`` when it meets the requirement."""
        return self.hi if req.smaller_is_better else self.lo


def seed_interval(req, runs, spread: Spread, *, scale: float = 1.0) -> Estimate | None:
    """Mean over seed runs with the 95 % interval of that mean (see the module notes).

    Parameters
    ----------
    req : Requirement
    runs : sequence of Evaluation
        One evaluation per seed (``value``, ``lo``, ``hi``, ``seconds``, ``status``); failed ones are left out.
    spread : Spread
        The task's pooled run-to-run variance.
    scale : float
        Multiplies the pooled variance (a smaller scene set varies more, see the worlds).

    Returns
    -------
    Estimate or None
        None without a finished run.
    """
    runs = [r for r in runs if r.status == "ok" and math.isfinite(r.value)]
    if not runs:
        return None
    vals = np.array([r.value for r in runs], dtype=float)
    k = len(vals)
    within = [w for w in (within_sd(req, r) for r in runs) if math.isfinite(w)]
    var_within = float(np.mean(np.square(within))) if within else 0.0
    var_pooled = spread.var * scale if math.isfinite(spread.var) else math.nan
    if math.isfinite(var_pooled) and var_pooled >= var_within:
        from scipy.stats import t as student

        var_run, q = var_pooled, float(student.ppf(0.975, max(spread.dof, 1)))
    else:
        var_run, q = var_within, Z95
    centre = metric_to_score(req, float(vals.mean()))
    half = q * math.sqrt(var_run / k)
    lo, hi = score_to_metric(req, centre - half), score_to_metric(req, centre + half)
    # an accuracy at the score's clip (0.001 or 0.999, e.g. every seed 100 %) keeps its mean inside its interval
    lo, hi = float(min(lo, float(vals.mean()))), float(max(hi, float(vals.mean())))
    return Estimate(float(vals.mean()), lo, hi, verdict(req, lo, hi), k, float(sum(r.seconds for r in runs)),
                    math.sqrt(var_run), q)


def rank_correlation(x, y) -> float:
    """Spearman's rank correlation of two equal-length sequences (0 where either is constant)."""
    from scipy.stats import rankdata

    x, y = np.asarray(x, float), np.asarray(y, float)
    if len(x) < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return 0.0
    rx, ry = rankdata(x), rankdata(y)
    c = np.corrcoef(rx, ry)[0, 1]
    return float(c) if math.isfinite(c) else 0.0
