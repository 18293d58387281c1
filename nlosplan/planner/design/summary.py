"""From a finished search to the answer: minimum requirement per parameter, cheapest design, Pareto fronts.

Minimum requirement per parameter: along each axis from the reference
design (the other parameters kept), the least hardware whose trained metric
meets the requirement, interpolated between the grid points around the
crossing (metric as log RMSE or logit accuracy, linear in the axis value, or
in its log for photons, bin width and zones). The interval comes from the
crossing of the metric's interval bounds (optimistic and pessimistic).
Zones and bin width are discrete: the least choice that meets, with the
interval from the choices where the optimistic and pessimistic bounds meet.
"""

from __future__ import annotations

import math

import numpy as np

from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.search import CONTINUOUS, MORE_IS_BETTER, DesignSearch, metric_to_score
from nlosplan.planner.design.space import AXES, Design

__all__ = ["summarize", "requirement_row", "pareto_front"]

_LOG_AXES = ("photon_fraction", "bin_factor", "zones")


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
    """The least hardware along one axis that meets ``req`` (see the module notes)."""
    pts = search.line_points(req, axis, search.base)
    if MORE_IS_BETTER[axis] is False:
        pts = pts[::-1]  # cheap -> costly
    pts = [p for p in pts if p["trained"] is not None or p["screened"]]
    xs = [p["x"] for p in pts]
    tv = [None if p["trained"] is None else p["trained"]["value"] for p in pts]
    opt = [None if p["trained"] is None else p["trained"]["lo" if req.smaller_is_better else "hi"] for p in pts]
    pes = [None if p["trained"] is None else p["trained"]["hi" if req.smaller_is_better else "lo"] for p in pts]
    discrete = axis not in CONTINUOUS and axis != "n_bins"
    value = _crossing(req, xs, tv, axis, discrete)
    a, b = _crossing(req, xs, opt, axis, discrete), _crossing(req, xs, pes, axis, discrete)
    kind = "minimum" if MORE_IS_BETTER[axis] else "maximum"
    unit = AXES[axis]["unit"]
    row = {"task": req.task, "requirement": req.name, "parameter": axis, "label": AXES[axis]["label"], "unit": unit,
           kind: value, "interval": None, "feasible": value is not None, "points": len(pts),
           "screened_out": sum(p["screened"] for p in pts),
           "note": ""}
    if value is not None:
        ends = [v for v in (a, b) if v is not None]
        i = xs.index(value) if value in xs else -1
        if i > 0 and tv[i - 1] is None:  # the cheaper neighbour was screened out: the threshold lies between
            ends.append(xs[i - 1])
            row["note"] = f"between {xs[i - 1]:.4g} (screened out by the bound) and {value:.4g}"
        if b is None:
            row["note"] = "the pessimistic bound never meets it within the range"
            ends.append(xs[-1])
        row["interval"] = [float(min(ends + [value])), float(max(ends + [value]))]
        if value == xs[0]:
            row["note"] = (row["note"] + "; " if row["note"] else "") + "met across the whole range (the limit is the space's)"
    elif pts:
        best = max((v for v in tv if v is not None), default=None, key=lambda v: -v if req.smaller_is_better else v)
        row["note"] = ("no tested value meets it" + (f" (best {best:.3g})" if best is not None else "")
                       + (f"; {row['screened_out']} screened out by the bound" if row["screened_out"] else ""))
    else:
        row["note"] = "not evaluated"
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
    designs = {Design.from_dict(r["design"]) for r in search.results.values()
               if r["task"] == req.task and r["evaluator"] == "trained"}
    out = []
    for d in designs:
        t = search.trained_value(req, d)
        if t is not None:
            out.append({"design": d, "key": d.key(), "cost": search.cost(d, search.space), **t})
    return sorted(out, key=lambda p: p["cost"])


def _cheapest(search: DesignSearch, req: Requirement, trained: list[dict]) -> dict:
    for c in search.candidates.get(req.name, []):
        t = search.trained_value(req, c["design"])
        if t is not None and req.met(t["value"]):
            return {"requirement": req.name, "task": req.task, "design": c["design"].to_dict(), "key": c["design"].key(),
                    "cost": search.cost(c["design"], search.space), **t, "source": "optimized, verified",
                    "margin": req.margin(t["value"])}
    meets = [p for p in trained if req.met(p["value"])]
    if meets:
        p = min(meets, key=lambda p: p["cost"])
        return {"requirement": req.name, "task": req.task, **{**p, "design": p["design"].to_dict()},
                "source": "scans (the optimized candidates did not verify)" if search.candidates.get(req.name)
                else "scans", "margin": req.margin(p["value"])}
    best = max(trained, key=lambda p: -p["value"] if req.smaller_is_better else p["value"], default=None)
    bounds = [r["value"] for r in search.results.values() if r["task"] == req.task and r["evaluator"] == "bound"
              and r["status"] == "ok" and math.isfinite(r["value"])]
    best_bound = (min(bounds) if req.smaller_is_better else max(bounds)) if bounds else None
    return {"requirement": req.name, "task": req.task, "design": None, "key": None, "cost": None, "value": None,
            "source": "none", "margin": None, "best_trained": None if best is None else best["value"],
            "best_bound": best_bound, "bound_meets": best_bound is not None and req.met(best_bound)}


def _curves(search: DesignSearch, req: Requirement) -> list[dict]:
    out = []
    for axis, layout, base, _ in search.lines():
        pts = search.line_points(req, axis, base)
        out.append({"requirement": req.name, "axis": axis, "zones": layout,
                    "points": [{"x": p["x"], "bound": p["bound"], "screened": p["screened"],
                                **({"value": p["trained"]["value"], "lo": p["trained"]["lo"], "hi": p["trained"]["hi"]}
                                   if p["trained"] else {"value": None, "lo": None, "hi": None})} for p in pts]})
    return out


def _evaluators(search: DesignSearch) -> list[dict]:
    rows = {}
    for r in search.results.values():
        k = (r["evaluator"], r["task"])
        rows.setdefault(k, []).append(r)
    out = []
    for (ev, task), rs in sorted(rows.items()):
        ok = [r for r in rs if r["status"] == "ok" and math.isfinite(r["value"])]
        half = [0.5 * (r["hi"] - r["lo"]) for r in ok if math.isfinite(r["hi"]) and math.isfinite(r["lo"])]
        out.append({"evaluator": ev, "task": task, "evaluations": len(rs), "ok": len(ok),
                    "unreachable": sum(r["status"] == "unreachable" for r in rs),
                    "failed": sum(r["status"] == "failed" for r in rs),
                    "median_seconds": float(np.median([r["seconds"] for r in rs])) if rs else math.nan,
                    "total_seconds": float(sum(r["seconds"] for r in rs)),
                    "median_half_interval": float(np.median(half)) if half else math.nan,
                    "fidelity": rs[0]["fidelity"]})
    return out


def summarize(search: DesignSearch) -> dict:
    """The answer of a finished search (JSON-ready apart from nothing: designs are dicts)."""
    rows, cheapest, pareto, curves, gaps = [], [], {}, [], {}
    for req in search.requirements:
        for axis in search.space.axes:
            rows.append(requirement_row(search, req, axis))
        trained = _designs_with_trained(search, req)
        cheapest.append(_cheapest(search, req, trained))
        pareto[req.name] = [{**p, "design": p["design"].to_dict()} for p in pareto_front(trained, req.smaller_is_better)]
        curves += _curves(search, req)
        gaps[req.name] = search.gap(req)
    failures = [{"key": r["key"], "evaluator": r["evaluator"], "task": r["task"],
                 "design": Design.from_dict(r["design"]).key(), "reason": r["reason"]}
                for r in search.results.values() if r["status"] == "failed"]
    disagreements = [row for req in search.requirements for row in search.disagreements(req)]
    unreachable = sorted({f"{Design.from_dict(r['design']).key()}: {r['reason']}"
                          for r in search.results.values() if r["status"] == "unreachable"})
    return {"requirements": rows, "cheapest": cheapest, "unreachable": unreachable, "disagreements": disagreements,
            "reference_bin_ps": search.space.sensor.bin_width_ps, "pareto": pareto, "curves": curves,
            "evaluators": _evaluators(search), "gap": gaps, "failures": failures,
            "optimize": [{k: v for k, v in r.items() if k != "design"} | {"design": r.get("design")}
                         for r in search.optimize_log],
            "reference_design": search.base.to_dict(), "reference_sensor": search.space.sensor.name,
            "requirements_asked": [r.name for r in search.requirements], "evaluations": len(search.results)}
