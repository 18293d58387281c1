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

__all__ = ["optimize_jobs", "optimize_choice", "collect_candidates"]


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
                                        {**knobs, "draws": max(100, knobs["draws"] // 2)},
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


def collect_candidates(evidence, results: list[dict], per_task: int) -> dict[str, list[Candidate]]:
    """Per requirement: the ``per_task`` cheapest feasible, distinct optimized designs, then the ``per_task``
    cheapest scanned designs whose learner meets it on average and is not already failed
    (:meth:`~nlosplan.planner.design.evidence.Evidence.scan_candidates`); each with its ``source``.

    ``results`` are :func:`optimize_choice`'s rows (an executor's failed row carries no design: left out).
    """
    out = {}
    for req in evidence.requirements:
        rows = sorted((r for r in results if r.get("requirement") == req.name and r.get("status") == "feasible"),
                      key=lambda r: r["cost"])
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
