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

import numpy as np

__all__ = ["MET", "NOT_MET", "UNDECIDED", "VERDICTS", "VERDICT_DEFINITIONS", "Spread", "verdict", "metric_to_score",
           "score_to_metric", "pooled_spread", "seed_interval", "rank_correlation"]

MET, NOT_MET, UNDECIDED = "met", "not met", "undecided"
VERDICTS = (MET, NOT_MET, UNDECIDED)
#: What each verdict means (the report's and the JSON's ``metric_definitions``).
VERDICT_DEFINITIONS = {
    MET: "the pessimistic end of the 95 % interval meets the requirement",
    NOT_MET: "even the optimistic end of the 95 % interval fails it",
    UNDECIDED: "the 95 % interval straddles the threshold (more seeds may decide it)",
}
_Z = 1.959963984540054


def verdict(req, lo: float, hi: float) -> str:
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


def _within_sd(req, rec: dict) -> float:
    """A run's own standard error on the score scale, from its bootstrap interval (NaN if none)."""
    lo, hi = rec.get("lo", math.nan), rec.get("hi", math.nan)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return math.nan
    return abs(metric_to_score(req, hi) - metric_to_score(req, lo)) / (2 * _Z)


def seed_interval(req, recs: list[dict], spread: Spread, *, scale: float = 1.0) -> dict | None:
    """Mean over seed runs with the 95 % interval of that mean (see the module notes).

    Parameters
    ----------
    req : Requirement
    recs : list of dict
        One evaluation record per seed (``value``, ``lo``, ``hi``, ``seconds``); failed ones are left out.
    spread : Spread
        The task's pooled run-to-run variance.
    scale : float
        Multiplies the pooled variance (a smaller scene set varies more, see the worlds).

    Returns
    -------
    dict or None
        ``value`` (mean of the runs), ``lo``, ``hi``, ``seeds``, ``seconds``, ``sd_run`` (one run's
        standard deviation on the score scale) and ``quantile``; None without a finished run.
    """
    recs = [r for r in recs if r.get("status", "ok") == "ok" and math.isfinite(r.get("value", math.nan))]
    if not recs:
        return None
    vals = np.array([r["value"] for r in recs], dtype=float)
    k = len(vals)
    within = [w for w in (_within_sd(req, r) for r in recs) if math.isfinite(w)]
    var_within = float(np.mean(np.square(within))) if within else 0.0
    var_pooled = spread.var * scale if math.isfinite(spread.var) else math.nan
    if math.isfinite(var_pooled) and var_pooled >= var_within:
        from scipy.stats import t as student

        var_run, q = var_pooled, float(student.ppf(0.975, max(spread.dof, 1)))
    else:
        var_run, q = var_within, _Z
    centre = metric_to_score(req, float(vals.mean()))
    half = q * math.sqrt(var_run / k)
    lo, hi = score_to_metric(req, centre - half), score_to_metric(req, centre + half)
    # an accuracy at the score's clip (0.001 or 0.999, e.g. every seed 100 %) keeps its mean inside its interval
    lo, hi = min(lo, float(vals.mean())), max(hi, float(vals.mean()))
    return {"value": float(vals.mean()), "lo": float(lo), "hi": float(hi), "seeds": k,
            "seconds": float(sum(r.get("seconds", 0.0) for r in recs)), "sd_run": math.sqrt(var_run), "quantile": q}


def rank_correlation(x, y) -> float:
    """Spearman's rank correlation of two equal-length sequences (0 where either is constant)."""
    from scipy.stats import rankdata

    x, y = np.asarray(x, float), np.asarray(y, float)
    if len(x) < 3 or np.ptp(x) == 0 or np.ptp(y) == 0:
        return 0.0
    rx, ry = rankdata(x), rankdata(y)
    c = np.corrcoef(rx, ry)[0, 1]
    return float(c) if math.isfinite(c) else 0.0
