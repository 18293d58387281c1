"""Stage 4 of the search: the cheapest design per task and discrete choice, by nlopt on the corrected bound.

For one requirement and one discrete choice (zones, bin width), COBYLA
(derivative-free, handles the constraint) varies three normalized
variables in [0, 1] — jitter (0: the space's smallest), log photon budget and
number of bins — to minimize the design's cost subject to the requirement
being met by the bound corrected with the measured bound-to-trained gap
(:meth:`~nlosplan.planner.design.evidence.Evidence.predict`). The costliest
corner is tried first: if even it misses, the choice is infeasible and
nothing else is evaluated. Jobs are :class:`~nlosplan.planner.design.jobs.OptimizeJob`
(typed, picklable), so the choices run in parallel on any executor.

Only the ``candidates`` cheapest feasible designs per requirement go on
(:func:`collect_candidates`), so :func:`run_optimize` is a branch and bound:
it offers the choices to the executor cheapest floor first (a choice's *floor* is the
cost of its cheapest setting, :func:`choice_floor`: no design of the choice
costs less), and skips a choice whose floor is above the ``candidates``-th
cheapest feasible design already found for its requirement -- nothing it
could find would be picked. On the main job this skips the 8x8 choices of the
shape task, whose 30-class ideal observer cost 5 of the stage's 10 CPU-minutes.
"""

from __future__ import annotations

import math
import time

import numpy as np

from nlosplan.planner.design.evaluation import Status
from nlosplan.planner.design.evaluators import evaluate
from nlosplan.planner.design.evidence import Candidate
from nlosplan.planner.design.jobs import OptimizeJob
from nlosplan.planner.design.space import Design, DesignSpace
from nlosplan.planner.design.verdicts import metric_to_score, score_to_metric

__all__ = ["optimize_jobs", "optimize_choice", "collect_candidates", "choice_floor", "run_optimize"]


def optimize_jobs(evidence, bound_job) -> list[OptimizeJob]:
    """One job per (requirement, zones, bin width) for :func:`optimize_choice`.

    Parameters
    ----------
    evidence : Evidence
        The search's evidence (the gap, the space, the cost).
    bound_job : callable
        ``bound_job(req, design)``: the search's bound job of a design (its knobs, reference, reference sensor).
    """
    jobs = []
    for req in evidence.requirements:
        gap = evidence.gap(req).value
        for z in evidence.space.zones:
            for f in evidence.space.bin_factors:
                base = evidence.base.replace(zones=z, bin_factor=f, n_bins=evidence.space.max_bins(f))
                proto = bound_job(req, base)
                knobs = {k: v for k, v in proto.fidelity.items() if k != "stop_at"}
                jobs.append(OptimizeJob(req, gap, evidence.space, evidence.cost_model, base,
                                        evidence.config.optimize_evals,
                                        {**knobs, "draws": max(100, knobs["draws"] // 4)},
                                        proto.reference, proto.reference_sensor))
    return jobs


def _design(u, base: Design, space: DesignSpace) -> Design:
    u = np.clip(np.asarray(u, float), 0.0, 1.0)
    jlo, jhi = space.jitter_fwhm_ps
    plo, phi = space.photon_fraction
    nlo, nhi = space.n_bins[0], space.max_bins(base.bin_factor)
    return base.replace(jitter_fwhm_ps=round(jlo + (1 - u[0]) * (jhi - jlo), 3),
                        photon_fraction=float(round(math.exp(math.log(plo) + u[1] * (math.log(phi) - math.log(plo))), 6)),
                        n_bins=int(round(nlo + u[2] * (max(nhi, nlo) - nlo))))


def optimize_choice(job: OptimizeJob) -> dict:
    """Cheapest design of one discrete choice meeting the corrected bound (see the module notes).

    Returns
    -------
    dict
        ``requirement`` (name), ``design`` (dict or None), ``cost``,
        ``predicted`` (trained metric predicted there), ``bound``,
        ``evaluations``, ``seconds``, ``status`` (``feasible``,
        ``infeasible`` or ``failed``) and ``reason``.
    """
    import nlopt

    t0 = time.perf_counter()
    req, space, cost_model, base = job.requirement, job.space, job.cost, job.base
    memo: dict[Design, tuple[float, float]] = {}

    def margin(u) -> tuple[float, float]:
        d = _design(u, base, space)
        if d not in memo:
            r = evaluate(job.bound_job(d))
            value = r["value"]
            if r["status"] != Status.OK or not math.isfinite(value):
                memo[d] = (-1.0, math.nan)
            else:
                pred = score_to_metric(req, metric_to_score(req, value) + job.gap)
                memo[d] = (req.margin(pred), value)
        return memo[d]

    out = {"requirement": req.name, "design": None, "cost": math.nan, "predicted": math.nan, "bound": math.nan,
           "status": "infeasible", "reason": "", "choice": f"{base.layout}, bin x{base.bin_factor}"}
    top = np.array([1.0, 1.0, 1.0])  # costliest corner: least jitter, most photons, most bins
    m_top, _ = margin(top)
    if not m_top >= 0:
        out.update(reason="even the costliest setting of this choice misses the corrected bound",
                   evaluations=len(memo), seconds=time.perf_counter() - t0)
        return out
    best = {"u": top, "cost": cost_model(_design(top, base, space), space)}

    def objective(u, grad):
        c = cost_model(_design(u, base, space), space)
        if margin(u)[0] >= 0 and c < best["cost"]:
            best.update(u=np.array(u), cost=c)
        return c

    opt = nlopt.opt(nlopt.LN_COBYLA, 3)
    opt.set_lower_bounds([0.0] * 3)
    opt.set_upper_bounds([1.0] * 3)
    opt.set_min_objective(objective)
    opt.add_inequality_constraint(lambda u, grad: -margin(u)[0], 0.0)
    opt.set_maxeval(int(job.max_evals))
    opt.set_initial_step(0.25)
    try:
        opt.optimize(top.copy())
    except (nlopt.RoundoffLimited, ValueError, RuntimeError) as exc:  # keep the best feasible point found
        out.update(reason=f"COBYLA stopped early ({type(exc).__name__})")
    d = _design(best["u"], base, space)
    m, b = margin(best["u"])
    pred = score_to_metric(req, metric_to_score(req, b) + job.gap)
    out.update(design=d.to_dict(), cost=best["cost"], predicted=pred, bound=b, status="feasible",
               evaluations=len(memo), seconds=time.perf_counter() - t0)
    return out


def choice_floor(job: OptimizeJob) -> float:
    """The cost of ``job``'s cheapest setting (most jitter, fewest photons, fewest bins): no design of its
    discrete choice costs less (the cost grows with every spec)."""
    return float(job.cost(_design(np.zeros(3), job.base, job.space), job.space))


def _feasible_cost(row: dict, requirement: str) -> float | None:
    """The cost of an optimize row's design when it is feasible for ``requirement`` (None otherwise)."""
    return row["cost"] if row.get("requirement") == requirement and row.get("status") == "feasible" else None


def _bar(rows: list[dict], requirement: str, per_task: int) -> float:
    """The ``per_task``-th cheapest feasible cost found for ``requirement`` (inf while fewer are known)."""
    costs = sorted(c for r in rows if (c := _feasible_cost(r, requirement)) is not None)
    return costs[per_task - 1] if len(costs) >= per_task else math.inf


def run_optimize(jobs: list[OptimizeJob], per_task: int, run) -> list[dict]:
    """Every job's row, cheapest floor first; a job whose floor is above its requirement's ``per_task``-th
    cheapest feasible cost found so far is not run (see the module notes).

    Parameters
    ----------
    jobs : list of OptimizeJob
    per_task : int
        Optimized candidates kept per requirement (``[search] candidates``).
    run : callable
        ``run(job iterator) -> iterator of (job, row)`` (:func:`optimize_choice`'s rows, e.g. an executor's
        ``map`` with ``ahead`` its workers): it takes a job only when it can start it, so each job is
        offered after the rows of the jobs finished before it.

    Returns
    -------
    list of dict
        The rows run and a ``pruned`` row per skipped job (``status`` ``"pruned"``, ``cost`` NaN, its
        ``floor`` and the ``bar`` it was above, both also said in the ``reason``), in the order decided.
    """
    if per_task < 1:
        raise ValueError(f"per_task={per_task} must be >= 1")
    rows: list[dict] = []

    def offered():
        for job in sorted(jobs, key=choice_floor):
            floor, bar = choice_floor(job), _bar(rows, job.requirement.name, per_task)
            if floor <= bar:
                yield job
                continue
            rows.append({"requirement": job.requirement.name, "design": None, "cost": math.nan,
                         "predicted": math.nan, "bound": math.nan, "status": "pruned",
                         "reason": f"its cheapest setting costs {floor:.2f}, above the {per_task} cheapest "
                                   f"feasible designs found ({bar:.2f})",
                         "choice": f"{job.base.layout}, bin x{job.base.bin_factor}", "evaluations": 0,
                         "seconds": 0.0, "floor": floor, "bar": bar})

    for _, row in run(offered()):
        rows.append(row)
    return rows


def collect_candidates(evidence, results: list[dict], per_task: int) -> dict[str, list[Candidate]]:
    """Per requirement: the ``per_task`` cheapest feasible, distinct optimized designs, then the ``per_task``
    cheapest scanned designs whose learner meets it on average and is not already failed
    (:meth:`~nlosplan.planner.design.evidence.Evidence.scan_candidates`); each with its ``source``.

    ``results`` are :func:`optimize_choice`'s rows (an executor's failed row carries no design: left out).
    """
    out = {}
    for req in evidence.requirements:
        rows = sorted((r for r in results if _feasible_cost(r, req.name) is not None),
                      key=lambda r: _feasible_cost(r, req.name))
        seen, picked = set(), []
        for r in rows:
            c = Candidate.from_dict({**r, "source": "optimized"})
            if c.design not in seen:
                seen.add(c.design)
                picked.append(c)
            if len(picked) >= per_task:
                break
        picked += [c for c in evidence.scan_candidates(req, per_task) if c.design not in seen]
        out[req.name] = picked
    return out
