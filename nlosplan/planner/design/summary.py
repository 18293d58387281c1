"""From a finished search to the answer: verdicts, minimum requirement per parameter, cheapest design, worlds.

Every answer is a three-valued verdict (:mod:`~nlosplan.planner.design.verdicts`).

Cheapest design per requirement: the cheapest candidate whose verdict is
*met* and that holds in at least ``quorum`` of the worlds
(:mod:`~nlosplan.planner.design.robust`); met in the nominal model but not
in enough worlds is *undecided* (what the model does not know decides it);
no met candidate but an undecided one: *undecided* (and why: the seeds or
the budget ran out); otherwise *not met*, with what the learners and the
bound reach (met by the bound but by no learner: "reachable in principle").

At DENALI's design point (``denali_point``) and the evaluators' consistency (``consistency``):
:mod:`~nlosplan.planner.design.denali_point`.

Minimum requirement per parameter: along each axis from the reference
design (the other parameters kept), the least hardware whose trained metric
meets the requirement, interpolated between the grid points around the
crossing (metric as log RMSE or logit accuracy, linear in the axis value, or
in its log for photons, bin width and zones). The interval comes from the
crossings of the metric's interval ends: *met* where the pessimistic end
crosses within the range, *undecided* where only the optimistic end does,
*not met* where neither does. Zones and bin width are discrete: the least
choice that meets, with the interval from the choices where the optimistic
and pessimistic ends meet. Values are in user units: zones as ``"3x3"``,
bin width in ps (``bin_width_ps``), photons as a fraction of the reference's.
"""

from __future__ import annotations

import math

import numpy as np

from nlosplan.planner.design import robust
from nlosplan.planner.design.denali_point import consistency, denali_point
from nlosplan.planner.design.evaluation import Evaluator, Status
from nlosplan.planner.design.evidence import Candidate, Evidence
from nlosplan.planner.design.lines import CONTINUOUS, MORE_IS_BETTER, lines, line_points
from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.space import AXES, Design, DesignSpace
from nlosplan.planner.design.verdicts import (MET, NOT_MET, UNDECIDED, VERDICT_DEFINITIONS, Estimate, Verdict,
                                              metric_to_score, seed_interval)

__all__ = ["summarize", "requirement_row", "pareto_front", "PARAMETERS", "metric_definitions", "user_design"]

_LOG_AXES = ("photon_fraction", "bin_factor", "zones")
#: The user's name and unit of each design axis (the JSON's ``parameter`` and ``unit``).
PARAMETERS: dict[str, tuple[str, str]] = {
    "zones": ("zones", "rows x columns"), "bin_factor": ("bin_width_ps", "ps"), "n_bins": ("n_bins", "bins"),
    "jitter_fwhm_ps": ("jitter_fwhm_ps", "ps"), "pulse_fwhm_ps": ("pulse_fwhm_ps", "ps"),
    "photon_fraction": ("photon_fraction", "fraction of the reference's photons per capture"),
}


def metric_definitions() -> dict:
    """The ``metric_definitions`` block: each metric and each verdict, defined once."""
    from nlosplan.tasks.metrics import METRIC_DEFINITIONS

    return {**METRIC_DEFINITIONS, **{f"verdict {k}": v for k, v in VERDICT_DEFINITIONS.items()}}


def user_design(d: Design | None, space: DesignSpace) -> dict | None:
    """A design in user units: zones ``"RxC"``, ``bin_width_ps``, ``n_bins``, jitter, pulse, photon fraction."""
    if d is None:
        return None
    return {"zones": d.layout, "bin_width_ps": d.bin_factor * space.sensor.bin_width_ps,
            "n_bins": d.n_bins, "jitter_fwhm_ps": d.jitter_fwhm_ps, "pulse_fwhm_ps": d.pulse_fwhm_ps,
            "photon_fraction": d.photon_fraction}


def _user_value(space: DesignSpace, axis: str, v):
    """An axis value in user units (a zone count as the layout's ``"RxC"``)."""
    if v is None:
        return None
    if axis == "zones":
        return next((f"{r}x{c}" for r, c in space.zones if r * c == round(v)), f"{v:g} zones")
    return float(v)


def _crossing(req: Requirement, xs, vals, axis: str, discrete: bool):
    """Axis value where the metric first meets the requirement walking from cheap to costly (None: never)."""
    meets = [v is not None and math.isfinite(v) and req.met(v) for v in vals]
    for i, ok in enumerate(meets):
        if not ok:
            continue
        if discrete or i == 0 or vals[i - 1] is None or not math.isfinite(vals[i - 1]):
            return xs[i]
        t0, t1, tt = metric_to_score(req, vals[i - 1]), metric_to_score(req, vals[i]), metric_to_score(req, req.threshold)
        if t1 == t0:
            return xs[i]
        frac = min(max((tt - t0) / (t1 - t0), 0.0), 1.0)
        if axis in _LOG_AXES:
            return float(math.exp(math.log(xs[i - 1]) + frac * (math.log(xs[i]) - math.log(xs[i - 1]))))
        return float(xs[i - 1] + frac * (xs[i] - xs[i - 1]))
    return None


def requirement_row(evidence: Evidence, req: Requirement, axis: str) -> dict:
    """The least hardware along one axis that meets ``req``, with its verdict (see the module notes)."""
    pts = line_points(evidence, req, axis, evidence.base)
    if MORE_IS_BETTER[axis] is False:
        pts = pts[::-1]  # cheap -> costly
    pts = [p for p in pts if p.judged]
    xs = [p.x for p in pts]
    tv = [None if p.trained is None else p.trained.value for p in pts]
    opt = [None if p.trained is None else p.trained.optimistic(req) for p in pts]
    pes = [None if p.trained is None else p.trained.pessimistic(req) for p in pts]
    discrete = axis not in CONTINUOUS and axis != "n_bins"
    value = _crossing(req, xs, tv, axis, discrete)
    a, b = _crossing(req, xs, opt, axis, discrete), _crossing(req, xs, pes, axis, discrete)
    kind = "minimum" if MORE_IS_BETTER[axis] else "maximum"
    name, unit = PARAMETERS[axis]
    verdict = MET if b is not None else (UNDECIDED if a is not None else NOT_MET)
    screened, implied = sum(p.screened for p in pts), sum(p.implied for p in pts)
    least, interval, notes = None, None, []
    if value is not None or a is not None:
        centre = value if value is not None else a
        ends = [v for v in (a, b, centre) if v is not None]
        i = xs.index(centre) if centre in xs else -1
        if i > 0 and tv[i - 1] is None:  # the cheaper neighbour was not trained: the threshold lies between
            ends.append(xs[i - 1])
            why = "screened out by the bound" if pts[i - 1].screened else "implied not met"
            notes.append(f"between {xs[i - 1]:.4g} ({why}) and {centre:.4g}")
        if b is None:
            notes.append("undecided: the pessimistic end of the interval never meets it within the range")
            ends.append(xs[-1])
        least = _user_value(evidence.space, axis, value)
        interval = [_user_value(evidence.space, axis, min(ends)), _user_value(evidence.space, axis, max(ends))]
        if verdict == MET and centre == xs[0]:
            notes.append("met across the whole range (the limit is the space's)")
    elif pts:
        best = max((v for v in tv if v is not None), default=None, key=lambda v: -v if req.smaller_is_better else v)
        notes.append("not met: even the optimistic end fails at every tested value"
                     + (f" (best {best:.3g})" if best is not None else "")
                     + (f"; {screened} screened out by the bound" if screened else ""))
    else:
        notes.append("not evaluated")
    return {"task": req.task, "requirement": req.name, "parameter": name, "axis": axis, "label": AXES[axis]["label"],
            "unit": unit, kind: least, "interval": interval, "verdict": verdict, "feasible": verdict == MET,
            "points": len(pts), "screened_out": screened, "implied_not_met": implied, "note": "; ".join(notes)}


def pareto_front(points: list[dict], smaller_is_better: bool) -> list[dict]:
    """Non-dominated points by (cost lower, value better), sorted by cost."""
    pts = sorted(points, key=lambda p: (p["cost"], p["value"] if smaller_is_better else -p["value"]))
    front, best = [], math.inf
    for p in pts:
        score = p["value"] if smaller_is_better else -p["value"]
        if score < best - 1e-12:
            front.append(p)
            best = score
    return front


def _estimate_fields(t: Estimate) -> dict:
    """An estimate as the JSON's design points carry it (the old ``trained_value`` dict, verdict last)."""
    return {"value": t.value, "lo": t.lo, "hi": t.hi, "seeds": t.seeds, "seconds": t.seconds, "sd_run": t.sd_run,
            "quantile": t.quantile, "verdict": t.verdict}


def _designs_with_trained(evidence: Evidence, req: Requirement) -> list[tuple[Design, float, Estimate]]:
    out = []
    for d in evidence.trained_designs(req):
        t = evidence.trained_value(req, d)
        if t is not None:
            out.append((d, evidence.cost(d), t))
    return sorted(out, key=lambda p: p[1])


def _fmt(req: Requirement, v: float) -> str:
    return f"{100 * v:.1f} cm" if req.smaller_is_better else f"{100 * v:.1f} %"


def _entry(evidence: Evidence, req: Requirement, c: Candidate, verdict: Verdict, decision: str,
           worlds: robust.WorldStatus | None = None) -> dict:
    tv = c.trained
    return {"requirement": req.name, "task": req.task, "verdict": verdict,
            "design": user_design(c.design, evidence.space), "key": c.design.key(), "cost": c.cost, "value": tv.value,
            "lo": tv.lo, "hi": tv.hi, "seeds": tv.seeds, "margin": req.margin(tv.value),
            "source": f"{c.source}, {tv.seeds} seed(s)", "decision": decision, "learner": evidence.learner(req.task),
            "worlds": None if worlds is None else {"met": worlds.met, "undecided": worlds.undecided,
                                                   "not_met": worlds.not_met, "worlds": worlds.worlds,
                                                   "needed": worlds.needed, "holds": worlds.holds,
                                                   "breaks": worlds.breaks}}


def _met_in_worlds(evidence: Evidence, req: Requirement, met: list[Candidate]) -> dict:
    """The cheapest met candidate that holds in the worlds, or *undecided* and why (see the module notes)."""
    ex = robust.examined(evidence, req)
    held = next((e for e in ex if e.status is not None and e.status.holds), None)
    if held is not None:
        decision = evidence.decision(req, held.candidate.trained)
        if held.design != met[0].design:
            first = ex[0].status
            decision += (f"; the cheaper {met[0].design.key()} is met in the nominal model but in only "
                         f"{first.met} of {first.worlds} worlds ({first.breaks})")
        return _entry(evidence, req, held.candidate, MET, decision, held.status)
    if ex and ex[-1].status is not None:
        st = ex[0].status
        return _entry(evidence, req, met[0], UNDECIDED, f"met in the nominal model, but in only {st.met} of "
                      f"{st.worlds} worlds (needs {st.needed}): {st.breaks}; {len(ex)} candidate(s) examined", st)
    return _entry(evidence, req, met[0], UNDECIDED,
                  "met in the nominal model; the worlds were not all evaluated (the run stopped)")


def _cheapest(evidence: Evidence, req: Requirement, trained: list[tuple[Design, float, Estimate]]) -> dict:
    cands = evidence.candidates(req)
    scans_only = not cands
    if scans_only:  # no candidate was verified (no optimize stage, or nothing met on the scans)
        cands = [Candidate(d, cost, "scans (not verified over seeds)", evidence.trained_value(req, d))
                 for d, cost, _ in trained]
    met = [c for c in cands if c.trained is not None and c.trained.verdict == MET]
    if met:
        if evidence.worlds is None or scans_only:
            return _entry(evidence, req, met[0], MET, evidence.decision(req, met[0].trained))
        return _met_in_worlds(evidence, req, met)
    undecided = [c for c in cands if c.trained is not None and c.trained.verdict == UNDECIDED]
    if undecided:
        c = undecided[0]
        why = (f"the cheapest undecided scan: {c.trained.seeds} run(s), its mean "
               f"{'meets' if req.met(c.trained.value) else 'misses'} it; no scanned design met it on average "
               "to be verified") if scans_only else evidence.decision(req, c.trained)
        return _entry(evidence, req, c, UNDECIDED, why)
    best = max((t.value for _, _, t in trained), key=lambda v: -v if req.smaller_is_better else v, default=None)
    bounds = [r.value for r in evidence.records() if r.task == req.task and r.evaluator is Evaluator.BOUND
              and r.finite]
    best_bound = (min(bounds) if req.smaller_is_better else max(bounds)) if bounds else None
    bound_meets = best_bound is not None and req.met(best_bound)
    learners = (f"today's learners ({', '.join(evidence.config.models)}; {evidence.learner(req.task)} chosen) "
                "reach")
    reach = f"{learners} {_fmt(req, best)} at best" if best is not None else "no learner was trained"
    bound = "the Cramér–Rao bound" if req.smaller_is_better else "the ideal observer"
    if bound_meets:
        note = f"reachable in principle ({bound} reaches {_fmt(req, best_bound)}); {reach}"
    else:
        note = (f"no design in the space meets it; {reach}"
                + (f"; {bound} reaches only {_fmt(req, best_bound)}" if best_bound is not None else ""))
    return {"requirement": req.name, "task": req.task, "verdict": NOT_MET, "design": None, "key": None, "cost": None,
            "value": None, "lo": None, "hi": None, "seeds": None, "margin": None, "source": "none",
            "decision": note, "learner": evidence.learner(req.task), "worlds": None, "best_trained": best,
            "best_bound": best_bound, "bound_meets": bound_meets}


def _curves(evidence: Evidence, req: Requirement) -> list[dict]:
    out = []
    for line in lines(evidence.space, evidence.base, evidence.config.grid_points):
        pts = line_points(evidence, req, line.axis, line.base)
        out.append({"requirement": req.name, "axis": line.axis, "parameter": PARAMETERS[line.axis][0],
                    "zones": line.layout,
                    "points": [{"x": p.x, "bound": p.bound, "screened": p.screened, "implied": p.implied,
                                **({"value": p.trained.value, "lo": p.trained.lo, "hi": p.trained.hi,
                                    "verdict": p.trained.verdict}
                                   if p.trained else {"value": None, "lo": None, "hi": None, "verdict": None})}
                               for p in pts]})
    return out


def _evaluators(evidence: Evidence) -> list[dict]:
    rows: dict[tuple, list] = {}
    for r in evidence.records():
        ev = r.evaluator + (" (worlds)" if r.world is not None else "")
        rows.setdefault((ev, r.task, r.model), []).append(r)
    out = []
    for (ev, task, model), rs in sorted(rows.items()):
        ok = [r for r in rs if r.finite]
        half = [0.5 * (r.hi - r.lo) for r in ok if math.isfinite(r.hi) and math.isfinite(r.lo)]
        out.append({"evaluator": ev, "task": task, "model": model, "evaluations": len(rs), "ok": len(ok),
                    "unreachable": sum(r.status is Status.UNREACHABLE for r in rs),
                    "failed": sum(r.status is Status.FAILED for r in rs),
                    "median_seconds": float(np.median([r.seconds for r in rs])) if rs else math.nan,
                    "total_seconds": float(sum(r.seconds for r in rs)),
                    "median_half_interval": float(np.median(half)) if half else math.nan,
                    "fidelity": rs[0].fidelity})
    return out


def _learner_table(evidence: Evidence) -> list[dict]:
    """Every candidate model on the reference design, per task: mean metric, interval, seconds, chosen."""
    rows = []
    for req in evidence.task_requirements():
        chosen = evidence.learner(req.task)
        for m in evidence.config.models:
            recs = [evidence.run(Evaluator.TRAINED, req, evidence.base, s, model=m)
                    for s in range(evidence.config.max_seeds)]
            tv = seed_interval(req, [r for r in recs if r is not None], evidence.spread(req))
            rows.append({"task": req.task, "requirement": req.name, "model": m, "chosen": m == chosen,
                         **({"value": tv.value, "lo": tv.lo, "hi": tv.hi, "seeds": tv.seeds,
                             "seconds_per_run": tv.seconds / tv.seeds} if tv else
                            {"value": None, "lo": None, "hi": None, "seeds": 0, "seconds_per_run": None})})
    return rows


def _disagreements(evidence: Evidence, req: Requirement) -> list[dict]:
    """Real against simulated trained metrics of the same designs (real captures only); ``disagree`` where their
    95 % intervals do not overlap."""
    rows = []
    for d in evidence.trained_designs(req):
        real, sim = evidence.trained_value(req, d), evidence.run(Evaluator.TRAINED_SIM, req, d)
        if real is None or sim is None or not sim.ok:
            continue
        rows.append({"requirement": req.name, "design": d.key(), "real": real.value, "real_lo": real.lo,
                     "real_hi": real.hi, "sim": sim.value, "sim_lo": sim.lo, "sim_hi": sim.hi,
                     "disagree": bool(real.hi < sim.lo or sim.hi < real.lo)})
    return rows


def _worlds_summary(evidence: Evidence) -> dict | None:
    wp = evidence.worlds
    if wp is None:
        return None
    rows = [{**r, "design": user_design(r["design"], evidence.space)} for r in robust.worlds_table(evidence)]
    return {"count": len(wp.drawn), "quorum": wp.config.quorum, "needed": wp.config.needed(),
            "scene_step": wp.config.scene_step, "scenes_per_world": wp.scenes.n_scenes,
            "variance_factor": wp.scene_ratio, "sources": wp.sources,
            "worlds": [{"world": w.index, "parameters": w.parameters} for w in wp.drawn], "candidates": rows}


def summarize(evidence: Evidence) -> dict:
    """The answer of a search's evidence (JSON-ready: designs in user units)."""
    rows, cheapest, pareto, curves, gaps = [], [], {}, [], {}
    space = evidence.space
    for req in evidence.requirements:
        rows += [requirement_row(evidence, req, axis) for axis in space.axes]
        trained = _designs_with_trained(evidence, req)
        cheapest.append(_cheapest(evidence, req, trained))
        points = [{"design": d, "key": d.key(), "cost": cost, **_estimate_fields(t)} for d, cost, t in trained]
        pareto[req.name] = [{**p, "design": user_design(p["design"], space)}
                            for p in pareto_front(points, req.smaller_is_better)]
        curves += _curves(evidence, req)
        gaps[req.name] = evidence.gap(req).to_dict()
    records = list(evidence.records())
    failures = [{"key": r.key, "evaluator": r.evaluator, "task": r.task, "design": r.design.key(), "reason": r.reason}
                for r in records if r.status is Status.FAILED]
    unreachable = sorted({f"{r.design.key()}: {r.reason}" for r in records if r.status is Status.UNREACHABLE})
    spreads = {}
    for req in evidence.requirements:
        sp = evidence.spread(req)
        spreads[req.name] = {"sd_score": sp.sd, "dof": sp.dof, "designs": sp.designs}
    base = user_design(evidence.base, space)
    return {"requirements": rows, "cheapest": cheapest, "unreachable": unreachable,
            "denali_point": [{**r, "design": base} for r in denali_point(evidence, cheapest)],
            "consistency": consistency(evidence),
            "disagreements": [row for req in evidence.requirements for row in _disagreements(evidence, req)],
            "reference_bin_ps": space.sensor.bin_width_ps, "pareto": pareto, "curves": curves,
            "evaluators": _evaluators(evidence), "gap": gaps, "failures": failures,
            "optimize": [{k: v for k, v in r.items() if k != "design"} | {"design": r.get("design")}
                         for r in evidence.optimize_log],
            "learners": _learner_table(evidence), "worlds": _worlds_summary(evidence), "spread": spreads,
            "budget": {"extra_evaluations": evidence.config.budget, "spent": evidence.extra_spent(),
                       "max_seeds": evidence.config.max_seeds,
                       "worlds_extra_evaluations": None if evidence.worlds is None else evidence.worlds.config.budget,
                       "worlds_spent": None if evidence.worlds is None else evidence.extra_spent(worlds=True)},
            "metric_definitions": metric_definitions(),
            "reference_design": user_design(evidence.base, space), "reference_sensor": space.sensor.name,
            "requirements_asked": [r.name for r in evidence.requirements], "evaluations": len(evidence)}
