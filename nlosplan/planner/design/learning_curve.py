"""The learning curve at the reference design: the task's learner trained on fewer and on more captures.

A verdict is about a sensor *and* a learner with a training budget. Every design of the search is judged with the
run's budget (:mod:`~nlosplan.planner.design.budget`: by default one capture per training scene, 2,100 for the main
job), because DENALI's budget at every design would cost about twelve times the learners' time. DENALI's Table 1
was reached with 25,200 training captures (:data:`DENALI_TRAIN_CAPTURES`), so at the reference design, the one
set beside Table 1, the run *measures* its learner along a ladder of budgets up to DENALI's
(:func:`curve_budgets`; the :attr:`~nlosplan.planner.design.evaluation.Evaluator.LEARNING_CURVE` evaluator, each
point with ``[search] curve_seeds`` seeds): a quarter and a half of the run's budget, four times it, and
DENALI's 25,200. No point is extrapolated: the figure at DENALI's budget is trained at DENALI's budget, and where it
is undecided the decide stage gives it more seeds (:func:`undecided_target_runs`), as it does a candidate.

What the curve says (:func:`curve_rows`, :func:`curve_summary`):

- ``denali_point``'s prediction is the learner at DENALI's budget where the curve reaches it (the like-for-like
  comparison with Table 1), and the row keeps the run's own budget's figure beside it;
- whether the run's verdicts, made at its own budget, look conservative: the metric at the largest budget is not
  worse than at the run's own (within its interval), so a design met at the run's budget would stay met with more
  captures as far as this design's curve shows (other designs' curves are not measured). Where it is worse, the
  report says so.

Simulated captures above the run's budget are more noisy captures of the same training scenes
(:func:`~nlosplan.planner.design.budget.training_set`); real captures cannot be drawn again, so with ``--real``
the ladder stops at the run's budget.
"""

from __future__ import annotations

from dataclasses import replace
from typing import NamedTuple

from nlosplan.planner.design.budget import MAX_TRAIN_CAPTURES, MIN_TRAIN_CAPTURES, TRAIN_CAPTURES
from nlosplan.planner.design.evaluation import Evaluator
from nlosplan.planner.design.evidence import Evidence
from nlosplan.planner.design.jobs import DesignJob
from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.verdicts import UNDECIDED, Estimate, seed_interval

__all__ = ["DENALI_TRAIN_CAPTURES", "curve_budgets", "run_budget", "curve_runs", "undecided_target_runs", "with_budget",
           "curve_estimates", "curve_rows", "curve_summary", "CurveSummary"]

#: DENALI's training side: 70 % of its 36,000 real captures (paper Table 1's budget).
DENALI_TRAIN_CAPTURES = 25_200


def curve_budgets(n_run: int, *, target: int = DENALI_TRAIN_CAPTURES, real: bool = False) -> list[int]:
    """The ladder of training budgets measured besides the run's own, ascending.

    Parameters
    ----------
    n_run : int
        The run's budget at the reference design (its learners' ``n_train``).
    target : int
        The budget to reach (DENALI's 25,200).
    real : bool
        Real training captures (``--real``): none can be drawn beyond the store, so nothing above ``n_run``.

    Returns
    -------
    list of int
        ``n_run // 4``, ``n_run // 2``, and (simulated only) ``4 n_run`` where that is below ``target``, and
        ``target`` where above ``n_run``; each from 2 to :data:`~nlosplan.resources.MAX_TRAIN_CAPTURES`,
        without ``n_run`` itself.

    Examples
    --------
    >>> curve_budgets(2100)
    [525, 1050, 8400, 25200]
    >>> curve_budgets(2100, real=True)
    [525, 1050]
    >>> curve_budgets(30000)
    [7500, 15000]
    """
    n = int(n_run)
    points = {n // 4, n // 2}
    if not real:
        if 4 * n < target:
            points.add(4 * n)
        if target > n:
            points.add(int(target))
    return sorted(p for p in points if MIN_TRAIN_CAPTURES <= p <= MAX_TRAIN_CAPTURES and p != n)


def run_budget(evidence: Evidence, req: Requirement) -> int | None:
    """The training captures the run's learner had at the reference design (its runs' ``n_train``; None: none)."""
    ns = [r.n_train for r in evidence.runs(req, evidence.base) if r.finite and r.n_train is not None]
    return max(ns) if ns else None


def curve_runs(evidence: Evidence) -> list[tuple[Requirement, int, int]]:
    """The learning curve's runs, ``(requirement, train_captures, i)``: for every requirement whose learner has run
    at the reference design, every budget of :func:`curve_budgets` at ``curve_seeds`` seeds (``i``: the run's
    index, as :meth:`~nlosplan.planner.design.search.DesignSearch.job` takes it)."""
    out = []
    for req in evidence.requirements:
        n_run = run_budget(evidence, req)
        if n_run is not None:
            out += [(req, n, i) for n in curve_budgets(n_run, real=evidence.has_real)
                    for i in range(evidence.config.curve_seeds)]
    return out


def undecided_target_runs(evidence: Evidence, per_round: int = 2) -> list[tuple[Requirement, int, int]]:
    """More seeds at DENALI's budget where the learner is undecided there, as the decide stage gives an undecided
    candidate: ``(requirement, DENALI_TRAIN_CAPTURES, i)``, ``per_round`` a round, up to ``max_seeds`` seeds (not
    charged to the run's budget of extra evaluations)."""
    out = []
    for req in evidence.requirements:
        at = curve_summary(req, curve_estimates(evidence, req)).at_target
        if at is not None and at.verdict == UNDECIDED:
            out += [(req, DENALI_TRAIN_CAPTURES, i) for i in range(at.seeds, min(at.seeds + per_round,
                                                                                evidence.config.max_seeds))]
    return out


def with_budget(job: DesignJob, captures: int) -> DesignJob:
    """``job`` training on ``captures`` (its knob ``train_captures``; the key follows)."""
    return replace(job, fidelity={**job.fidelity, TRAIN_CAPTURES: int(captures)})


def curve_estimates(evidence: Evidence, req: Requirement) -> list[tuple[int, Estimate, bool]]:
    """The learner's mean metric at each budget measured at the reference design, ascending.

    Returns
    -------
    list of (train_captures, Estimate, is_run_budget)
        The run's own budget (its trained runs) and every ladder point with a finished run.
    """
    n_run = run_budget(evidence, req)
    if n_run is None:
        return []
    spread, out = evidence.spread(req), []
    own = evidence.trained_value(req, evidence.base)
    if own is not None:
        out.append((n_run, own, True))
    for n in curve_budgets(n_run, real=evidence.has_real):
        runs = [evidence.run(Evaluator.LEARNING_CURVE, req, evidence.base, i, budget=n)
                for i in range(max(evidence.config.curve_seeds, evidence.config.max_seeds))]
        est = seed_interval(req, [r for r in runs if r is not None], spread)
        if est is not None:
            out.append((n, est, False))
    return sorted(out, key=lambda t: t[0])


def curve_rows(evidence: Evidence, req: Requirement) -> list[dict]:
    """:func:`curve_estimates` as ``result.json`` rows: ``train_captures``, ``value``, ``lo``, ``hi`` (metres or a
    fraction), ``seeds``, ``verdict`` (against ``req``), ``run_budget`` (the run's own budget's point)."""
    return [{"train_captures": n, "value": e.value, "lo": e.lo, "hi": e.hi, "seeds": e.seeds, "verdict": e.verdict,
             "run_budget": own} for n, e, own in curve_estimates(evidence, req)]


class CurveSummary(NamedTuple):
    """What a requirement's learning curve says (:func:`curve_summary`).

    Attributes
    ----------
    at_target : Estimate or None
        The learner at DENALI's budget (None: not on the curve).
    conservative : bool or None
        True: the largest budget's interval reaches at least the run's own figure (more captures did not make the
        learner worse on this curve); None: nothing to compare.
    gain : float or None
        The largest budget's metric minus the run's own (metres or a fraction).
    """

    at_target: Estimate | None
    conservative: bool | None
    gain: float | None


def curve_summary(req: Requirement, points: list[tuple[int, Estimate, bool]],
                  target: int = DENALI_TRAIN_CAPTURES) -> CurveSummary:
    """:class:`CurveSummary` of :func:`curve_estimates`' ``points`` (ascending) at DENALI's budget ``target``."""
    at = next((e for n, e, _ in points if n == target), None)
    own = next((e for _, e, is_own in points if is_own), None)
    largest = points[-1][1] if points else None
    if own is None or largest is None or largest is own:
        return CurveSummary(at, None, None)
    ok = largest.lo <= own.value if req.smaller_is_better else largest.hi >= own.value
    return CurveSummary(at, bool(ok), float(largest.value - own.value))
