"""From a finished search to the answer: verdicts, minimum requirement per parameter, cheapest design, worlds.

Every answer is a three-valued verdict (:mod:`~nlosplan.planner.design.verdicts`).

Cheapest design per requirement: the cheapest candidate whose verdict is
*met* and that holds in at least ``quorum`` of the worlds
(:mod:`~nlosplan.planner.design.robust`); met in the nominal model but not
in enough worlds is *undecided* (what the model does not know decides it);
no met candidate but an undecided one: *undecided* (and why: the seeds or
the budget ran out); otherwise *not met*, with what the learners and the
bound reach (met by the bound but by no learner: "reachable in principle").

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
from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.search import CONTINUOUS, MORE_IS_BETTER, DesignSearch
from nlosplan.planner.design.space import AXES, Design
from nlosplan.planner.design.verdicts import (MET, NOT_MET, UNDECIDED, VERDICT_DEFINITIONS, metric_to_score)

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


def user_design(d: Design | None, search: DesignSearch) -> dict | None:
    """A design in user units: zones ``"RxC"``, ``bin_width_ps``, ``n_bins``, jitter, pulse, photon fraction."""
    if d is None:
        return None
    return {"zones": f"{d.zones[0]}x{d.zones[1]}", "bin_width_ps": d.bin_factor * search.space.sensor.bin_width_ps,
            "n_bins": d.n_bins, "jitter_fwhm_ps": d.jitter_fwhm_ps, "pulse_fwhm_ps": d.pulse_fwhm_ps,
            "photon_fraction": d.photon_fraction}


def _user_value(search: DesignSearch, axis: str, v):
    """An axis value in user units (a zone count as the layout's ``"RxC"``)."""
    if v is None:
        return None
    if axis == "zones":
        return next((f"{r}x{c}" for r, c in search.space.zones if r * c == round(v)), f"{v:g} zones")
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


def requirement_row(search: DesignSearch, req: Requirement, axis: str) -> dict:
    """The least hardware along one axis that meets ``req``, with its verdict (see the module notes)."""
    pts = search.line_points(req, axis, search.base)
    if MORE_IS_BETTER[axis] is False:
        pts = pts[::-1]  # cheap -> costly
    pts = [p for p in pts if p["trained"] is not None or p["screened"] or p["implied"]]
    xs = [p["x"] for p in pts]
    tv = [None if p["trained"] is None else p["trained"]["value"] for p in pts]
    opt = [None if p["trained"] is None else p["trained"]["lo" if req.smaller_is_better else "hi"] for p in pts]
    pes = [None if p["trained"] is None else p["trained"]["hi" if req.smaller_is_better else "lo"] for p in pts]
    discrete = axis not in CONTINUOUS and axis != "n_bins"
    value = _crossing(req, xs, tv, axis, discrete)
    a, b = _crossing(req, xs, opt, axis, discrete), _crossing(req, xs, pes, axis, discrete)
    kind = "minimum" if MORE_IS_BETTER[axis] else "maximum"
    name, unit = PARAMETERS[axis]
    verdict = MET if b is not None else (UNDECIDED if a is not None else NOT_MET)
    row = {"task": req.task, "requirement": req.name, "parameter": name, "axis": axis, "label": AXES[axis]["label"],
           "unit": unit, kind: None, "interval": None, "verdict": verdict, "feasible": verdict == MET,
           "points": len(pts), "screened_out": sum(p["screened"] for p in pts),
           "implied_not_met": sum(p["implied"] for p in pts), "note": ""}
    notes = []
    if value is not None or a is not None:
        centre = value if value is not None else a
        ends = [v for v in (a, b, centre) if v is not None]
        i = xs.index(centre) if centre in xs else -1
        if i > 0 and tv[i - 1] is None:  # the cheaper neighbour was not trained: the threshold lies between
            ends.append(xs[i - 1])
            why = "screened out by the bound" if pts[i - 1]["screened"] else "implied not met"
            notes.append(f"between {xs[i - 1]:.4g} ({why}) and {centre:.4g}")
        if b is None:
            notes.append("undecided: the pessimistic end of the interval never meets it within the range")
            ends.append(xs[-1])
        lo_end, hi_end = min(ends), max(ends)
        row[kind] = _user_value(search, axis, value)
        row["interval"] = [_user_value(search, axis, lo_end), _user_value(search, axis, hi_end)]
        if verdict == MET and centre == xs[0]:
            notes.append("met across the whole range (the limit is the space's)")
    elif pts:
        best = max((v for v in tv if v is not None), default=None, key=lambda v: -v if req.smaller_is_better else v)
        notes.append("not met: even the optimistic end fails at every tested value"
                     + (f" (best {best:.3g})" if best is not None else "")
                     + (f"; {row['screened_out']} screened out by the bound" if row["screened_out"] else ""))
    else:
        notes.append("not evaluated")
    row["note"] = "; ".join(notes)
    return row


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


def _designs_with_trained(search: DesignSearch, req: Requirement) -> list[dict]:
    out = []
    for d in search.trained_designs(req):
        t = search.trained_value(req, d)
        if t is not None:
            out.append({"design": d, "key": d.key(), "cost": search.cost(d, search.space), **t})
    return sorted(out, key=lambda p: p["cost"])


def _fmt(req: Requirement, v: float) -> str:
    return f"{100 * v:.1f} cm" if req.smaller_is_better else f"{100 * v:.1f} %"


def _entry(search, req, c: dict, verdict: str, decision: str, source: str) -> dict:
    tv = c["trained"]
    return {"requirement": req.name, "task": req.task, "verdict": verdict, "design": user_design(c["design"], search),
            "key": c["design"].key(), "cost": c["cost"], "value": tv["value"], "lo": tv["lo"], "hi": tv["hi"],
            "seeds": tv["seeds"], "margin": req.margin(tv["value"]), "source": source, "decision": decision,
            "learner": search.learner(req.task), "worlds": None}


def _worlds_of(st: dict | None) -> dict | None:
    if st is None:
        return None
    return {k: st[k] for k in ("met", "undecided", "not_met", "worlds", "needed", "holds", "breaks")}


def _cheapest(search: DesignSearch, req: Requirement, trained: list[dict]) -> dict:
    cands = search.ordered_candidates(req)
    scans_only = not cands
    if scans_only:  # no candidate was verified (no optimize stage, or nothing met on the scans)
        cands = [{"design": p["design"], "cost": p["cost"], "source": "scans (not verified over seeds)",
                  "trained": search.trained_value(req, p["design"])} for p in trained]
    met = [c for c in cands if c["trained"] is not None and c["trained"]["verdict"] == MET]
    src = lambda c: f"{c.get('source', 'scans')}, {c['trained']['seeds']} seed(s)"  # noqa: E731
    if met:
        if search.worlds is None or scans_only:
            c = met[0]
            return _entry(search, req, c, MET, search.decision(req, c["trained"]), src(c))
        ex = robust.examined(search, req)
        held = next((e for e in ex if e["status"] is not None and e["status"]["holds"]), None)
        if held is not None:
            out = _entry(search, req, held, MET, search.decision(req, held["trained"]), src(held))
            out["worlds"] = _worlds_of(held["status"])
            if held["design"] != met[0]["design"]:
                first = ex[0]["status"]
                out["decision"] += (f"; the cheaper {met[0]['design'].key()} is met in the nominal model but in only "
                                    f"{first['met']} of {first['worlds']} worlds ({first['breaks']})")
            return out
        last = ex[-1] if ex else None
        c = met[0]
        out = _entry(search, req, c, UNDECIDED, search.decision(req, c["trained"]), src(c))
        if last is not None and last["status"] is not None:
            st = ex[0]["status"]
            out["worlds"] = _worlds_of(st)
            out["decision"] = (f"met in the nominal model, but in only {st['met']} of {st['worlds']} worlds "
                               f"(needs {st['needed']}): {st['breaks']}; {len(ex)} candidate(s) examined")
        else:
            out["decision"] = "met in the nominal model; the worlds were not all evaluated (the run stopped)"
        return out
    undecided = [c for c in cands if c["trained"] is not None and c["trained"]["verdict"] == UNDECIDED]
    if undecided:
        c = undecided[0]
        why = (f"the cheapest undecided scan: {c['trained']['seeds']} run(s), its mean "
               f"{'meets' if req.met(c['trained']['value']) else 'misses'} it; no scanned design met it on average "
               "to be verified") if scans_only else search.decision(req, c["trained"])
        return _entry(search, req, c, UNDECIDED, why, src(c))
    best = max(trained, key=lambda p: -p["value"] if req.smaller_is_better else p["value"], default=None)
    bounds = [r["value"] for r in search.results.values() if r["task"] == req.task and r["evaluator"] == "bound"
              and r["status"] == "ok" and math.isfinite(r["value"])]
    best_bound = (min(bounds) if req.smaller_is_better else max(bounds)) if bounds else None
    bound_meets = best_bound is not None and req.met(best_bound)
    learners = f"today's learners ({', '.join(search.config.models)}; {search.learner(req.task)} chosen) reach"
    reach = f"{learners} {_fmt(req, best['value'])} at best" if best is not None else "no learner was trained"
    bound = "the Cramér–Rao bound" if req.smaller_is_better else "the ideal observer"
    if bound_meets:
        note = f"reachable in principle ({bound} reaches {_fmt(req, best_bound)}); {reach}"
    else:
        note = (f"no design in the space meets it; {reach}"
                + (f"; {bound} reaches only {_fmt(req, best_bound)}" if best_bound is not None else ""))
    return {"requirement": req.name, "task": req.task, "verdict": NOT_MET, "design": None, "key": None, "cost": None,
            "value": None, "lo": None, "hi": None, "seeds": None, "margin": None, "source": "none",
            "decision": note, "learner": search.learner(req.task), "worlds": None,
            "best_trained": None if best is None else best["value"], "best_bound": best_bound,
            "bound_meets": bound_meets}


def _curves(search: DesignSearch, req: Requirement) -> list[dict]:
    out = []
    for axis, layout, base, _ in search.lines():
        pts = search.line_points(req, axis, base)
        out.append({"requirement": req.name, "axis": axis, "parameter": PARAMETERS[axis][0], "zones": layout,
                    "points": [{"x": p["x"], "bound": p["bound"], "screened": p["screened"], "implied": p["implied"],
                                **({"value": p["trained"]["value"], "lo": p["trained"]["lo"], "hi": p["trained"]["hi"],
                                    "verdict": p["trained"]["verdict"]}
                                   if p["trained"] else {"value": None, "lo": None, "hi": None, "verdict": None})}
                               for p in pts]})
    return out


def _evaluators(search: DesignSearch) -> list[dict]:
    rows = {}
    for r in search.results.values():
        ev = r["evaluator"] + (" (worlds)" if r.get("world") is not None else "")
        model = r["fidelity"].get("model", "") if r["evaluator"] != "bound" else ""
        rows.setdefault((ev, r["task"], model), []).append(r)
    out = []
    for (ev, task, model), rs in sorted(rows.items()):
        ok = [r for r in rs if r["status"] == "ok" and math.isfinite(r["value"])]
        half = [0.5 * (r["hi"] - r["lo"]) for r in ok if math.isfinite(r["hi"]) and math.isfinite(r["lo"])]
        out.append({"evaluator": ev, "task": task, "model": model, "evaluations": len(rs), "ok": len(ok),
                    "unreachable": sum(r["status"] == "unreachable" for r in rs),
                    "failed": sum(r["status"] == "failed" for r in rs),
                    "median_seconds": float(np.median([r["seconds"] for r in rs])) if rs else math.nan,
                    "total_seconds": float(sum(r["seconds"] for r in rs)),
                    "median_half_interval": float(np.median(half)) if half else math.nan,
                    "fidelity": rs[0]["fidelity"]})
    return out


def _worlds_summary(search: DesignSearch) -> dict | None:
    wp = search.worlds
    if wp is None:
        return None
    rows = robust.worlds_table(search)
    for r in rows:
        r["design"] = user_design(r["design"], search)
    return {"count": len(wp.drawn), "quorum": wp.config.quorum, "needed": wp.config.needed(),
            "scene_step": wp.config.scene_step, "scenes_per_world": wp.scenes.n_scenes,
            "variance_factor": wp.scene_ratio, "sources": wp.sources,
            "worlds": [{"world": w.index, "parameters": w.parameters} for w in wp.drawn], "candidates": rows}


def summarize(search: DesignSearch) -> dict:
    """The answer of a finished search (JSON-ready: designs in user units)."""
    rows, cheapest, pareto, curves, gaps = [], [], {}, [], {}
    for req in search.requirements:
        for axis in search.space.axes:
            rows.append(requirement_row(search, req, axis))
        trained = _designs_with_trained(search, req)
        cheapest.append(_cheapest(search, req, trained))
        pareto[req.name] = [{**p, "design": user_design(p["design"], search)}
                            for p in pareto_front(trained, req.smaller_is_better)]
        curves += _curves(search, req)
        gaps[req.name] = search.gap(req)
    failures = [{"key": r["key"], "evaluator": r["evaluator"], "task": r["task"],
                 "design": Design.from_dict(r["design"]).key(), "reason": r["reason"]}
                for r in search.results.values() if r["status"] == "failed"]
    disagreements = [row for req in search.requirements for row in search.disagreements(req)]
    unreachable = sorted({f"{Design.from_dict(r['design']).key()}: {r['reason']}"
                          for r in search.results.values() if r["status"] == "unreachable"})
    spreads = {req.name: {"sd_score": search.spread(req).sd, "dof": search.spread(req).dof,
                          "designs": search.spread(req).designs} for req in search.requirements}
    return {"requirements": rows, "cheapest": cheapest, "unreachable": unreachable, "disagreements": disagreements,
            "reference_bin_ps": search.space.sensor.bin_width_ps, "pareto": pareto, "curves": curves,
            "evaluators": _evaluators(search), "gap": gaps, "failures": failures,
            "optimize": [{k: v for k, v in r.items() if k != "design"} | {"design": r.get("design")}
                         for r in search.optimize_log],
            "learners": search.learner_table(), "worlds": _worlds_summary(search), "spread": spreads,
            "budget": {"extra_evaluations": search.config.budget, "spent": search.extra_spent(),
                       "max_seeds": search.config.max_seeds},
            "metric_definitions": metric_definitions(),
            "reference_design": user_design(search.base, search), "reference_sensor": search.space.sensor.name,
            "requirements_asked": [r.name for r in search.requirements], "evaluations": len(search.results)}
