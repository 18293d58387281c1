"""The worlds stage of the search: are the cheapest met candidates met in the plausible worlds?

For each requirement, its candidates whose verdict is *met* are examined
cheapest first (at most ``[worlds] candidates``): each is evaluated in every
world (:mod:`~nlosplan.planner.design.worlds`) and in world 0 (the nominal
model at the worlds' scenes) at the same seeds, and its metric in world
``w`` is its verified value shifted by the paired difference (see the worlds
module). A world's verdict is the three-valued one of that interval; an
undecided world gets one more seed pair while the run's budget lasts. The
first candidate met in at least ``quorum`` of the worlds is the
requirement's minimum hardware. Once a candidate fails, the next one is not
simply the next cheapest (at the requirement's margin those fail alike, and
which of them a seed happens to examine decided the answer): it is the
cheapest design verified *met* anywhere in the search (optimized, or on the
scans) whose pessimistic margin exceeds the largest loss any world caused
to the candidates examined so far, else the one with the largest margin
(:func:`next_candidate`); so the examination climbs to a design robust to
the worlds instead of stopping at the margin; for each candidate the report says in how
many worlds it holds and which world parameter breaks it (the one whose
values rank most closely with the candidate's margin across the worlds).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from nlosplan.planner.design.data import SceneSet
from nlosplan.planner.design.verdicts import (_Z, MET, NOT_MET, UNDECIDED, _within_sd, metric_to_score,
                                              rank_correlation, score_to_metric, verdict)
from nlosplan.planner.design.worlds import World, WorldsConfig

__all__ = ["WorldPlan", "world_jobs", "needed_references", "world_value", "world_status", "examined", "worlds_table"]


@dataclass
class WorldPlan:
    """The worlds of a run and where their references are.

    Attributes
    ----------
    config : WorldsConfig
    worlds : list of World
        World 0 (nominal, the control) first, then the drawn ones.
    scenes : SceneSet
        The worlds' scenes (no bound scenes; each world adds its ``scene_kwargs``).
    scene_ratio : float
        The run's scenes over the worlds' scenes: how much more one run on them varies.
    references : dict
        ``(world index, layout) -> path`` of the simulated references (world 0 may be the run's own).
    sources : list of str
        Where the worlds' parameters come from (ranges, a calibration's uncertainty).
    """

    config: WorldsConfig
    worlds: list
    scenes: SceneSet
    scene_ratio: float
    references: dict = field(default_factory=dict)
    sources: list = field(default_factory=list)

    @property
    def drawn(self) -> list[World]:
        return self.worlds[1:]


def _job(search, req, d, w: World, i: int):
    """The job of ``d``'s ``i``-th run in world ``w`` (None until its reference exists)."""
    wp = search.worlds
    layout = search._layout(d)
    ref = wp.references.get((w.index, layout))
    if ref is None:
        return None
    if w.index == 0 and str(ref) == str(search.trained_references.get(layout)):
        return search.job("trained", req, d, i)  # world 0 is the run's own reference: its own runs
    return search.job("trained", req, d, i, reference=str(ref), world=dict(w.sensor))


def world_value(search, req, d, w: World) -> dict | None:
    """``d``'s metric in world ``w``: verified value + paired world effect, with interval and verdict."""
    nominal = search.trained_value(req, d)
    if nominal is None:
        return None
    control = search.worlds.worlds[0]
    pairs, present = [], 0
    for i in range(search.config.max_seeds):
        jw, j0 = _job(search, req, d, w, i), _job(search, req, d, control, i)
        rw = None if jw is None else search.results.get(jw.key)
        r0 = None if j0 is None else search.results.get(j0.key)
        if rw is None or r0 is None:
            break
        present += 1
        if all(r["status"] == "ok" and math.isfinite(r["value"]) for r in (rw, r0)):
            pairs.append((rw, r0))
    if not present:
        return None
    if not pairs:  # every run failed: recorded, undecided
        return {"value": math.nan, "lo": math.nan, "hi": math.nan, "verdict": UNDECIDED, "seeds": 0,
                "runs": present, "effect": math.nan}
    diffs = [metric_to_score(req, a["value"]) - metric_to_score(req, b["value"]) for a, b in pairs]
    m = len(diffs)
    spread = search.spread(req)
    within = [s ** 2 for a, b in pairs for s in (_within_sd(req, a), _within_sd(req, b)) if math.isfinite(s)]
    var_within = sum(within) / len(within) if within else 0.0
    pooled = spread.var * search.worlds.scene_ratio if math.isfinite(spread.var) else math.nan
    if math.isfinite(pooled) and pooled >= var_within:
        from scipy.stats import t as student

        var_run, q = pooled, float(student.ppf(0.975, max(spread.dof, 1)))
    else:
        var_run, q = var_within, _Z
    centre = metric_to_score(req, nominal["value"]) + sum(diffs) / m
    half = q * math.sqrt(nominal["sd_run"] ** 2 / nominal["seeds"] + 2.0 * var_run / m)
    lo, hi = score_to_metric(req, centre - half), score_to_metric(req, centre + half)
    return {"value": score_to_metric(req, centre), "lo": lo, "hi": hi, "verdict": verdict(req, lo, hi),
            "seeds": m, "runs": present, "effect": sum(diffs) / m}


def _can_extend(search, wv: dict | None) -> bool:
    return (wv is not None and wv["verdict"] == UNDECIDED and wv["runs"] < search.config.max_seeds
            and search.budget_left() >= 2)


def world_status(search, req, d) -> dict | None:
    """In how many worlds ``d`` is met, and whether it holds (None while its evaluations are not all in)."""
    wp = search.worlds
    per = [world_value(search, req, d, w) for w in wp.drawn]
    if any(v is None or _can_extend(search, v) for v in per):
        return None
    met = sum(v["verdict"] == MET for v in per)
    return {"met": met, "not_met": sum(v["verdict"] == NOT_MET for v in per),
            "undecided": sum(v["verdict"] == UNDECIDED for v in per), "worlds": len(per),
            "needed": wp.config.needed(), "holds": met >= wp.config.needed(), "per_world": per,
            **_attribution(req, wp.drawn, per)}


def _attribution(req, worlds, per) -> dict:
    """The world parameter that ranks most closely with the margin, and where it breaks the design."""
    names = sorted({n for w in worlds for n in w.parameters})
    ok = [i for i, v in enumerate(per) if math.isfinite(v["value"])]
    margins = [req.margin(per[i]["value"]) for i in ok]
    rho = {n: rank_correlation([worlds[i].parameters.get(n, math.nan) for i in ok], margins) for n in names}
    failing = [i for i, v in enumerate(per) if v["verdict"] == NOT_MET]
    straddling = [i for i, v in enumerate(per) if v["verdict"] == UNDECIDED]
    if not names:
        return {"sensitivity": {}, "breaks": ""}
    driver = max(names, key=lambda n: (abs(rho[n]), n))
    follows = f"the margin follows {driver} most (Spearman {rho[driver]:+.2f})" if abs(rho[driver]) > 0 else ""
    undecided = (f"undecided in worlds {', '.join(str(worlds[i].index) for i in straddling)} (the interval "
                 "straddles the threshold when the seeds or the budget ran out)") if straddling else ""
    if not failing:  # no world fails it: no parameter is blamed for intervals that are only too wide
        text = "; ".join(t for t in (undecided or "met in every world", follows) if t)
        return {"sensitivity": rho, "breaks": text, "driver": driver}
    vals = [worlds[i].parameters.get(driver, math.nan) for i in failing]
    worst = max(vals) if rho[driver] > 0 else min(vals)
    side = "<=" if rho[driver] > 0 else ">="
    text = (f"{driver} {side} {worst:.3g} breaks it (not met in worlds "
            f"{', '.join(str(worlds[i].index) for i in failing)}; Spearman {rho[driver]:+.2f} with the margin)"
            + (f"; {undecided}" if undecided else ""))
    return {"sensitivity": rho, "breaks": text, "driver": driver}


def _goodness(req, value: float) -> float:
    """The score of a metric value oriented so that higher is better (log RMSE negated, logit accuracy)."""
    z = metric_to_score(req, value)
    return -z if req.smaller_is_better else z


def worst_loss(req, done: list[dict]) -> float:
    """The largest loss (score scale, >= 0) a world caused to any candidate in ``done`` (complete statuses)."""
    worst = 0.0
    for c in done:
        for v in (c["status"] or {}).get("per_world", []):
            e = v.get("effect", math.nan)
            if math.isfinite(e):
                worst = max(worst, e if req.smaller_is_better else -e)
    return worst


def next_candidate(search, req, done: list[dict]) -> dict | None:
    """After a failed candidate: the cheapest met design whose pessimistic margin exceeds the worst world loss.

    Candidates are every design of the task verified *met* (the optimized and scanned candidates and the
    scans' trained designs) not examined yet; the margin is on the score scale, from the pessimistic end of
    the design's interval. None fit: the one with the largest margin (None when nothing is left).
    """
    seen = {c["design"] for c in done}
    loss = worst_loss(req, done)
    threshold = _goodness(req, req.threshold)
    pool = {c["design"]: c for c in search.ordered_candidates(req)}
    for d in search.trained_designs(req):
        if d not in pool:
            pool[d] = {"design": d, "cost": search.cost(d, search.space), "trained": search.trained_value(req, d),
                       "source": "scans, examined after a cheaper candidate failed in the worlds"}
    rows = []
    for d, c in pool.items():
        tv = c["trained"]
        if d in seen or tv is None or tv["verdict"] != MET:
            continue
        pessimistic = tv["hi"] if req.smaller_is_better else tv["lo"]
        rows.append((_goodness(req, pessimistic) - threshold, c))
    if not rows:
        return None
    robust_enough = [c for m, c in rows if m > loss]
    if robust_enough:
        return min(robust_enough, key=lambda c: (c["cost"], c["design"]))
    return max(rows, key=lambda r: (r[0], -r[1]["cost"]))[1]


def examined(search, req) -> list[dict]:
    """The requirement's met candidates in the order the worlds examine them, each with its ``status``.

    The cheapest met candidate first; after a candidate that does not hold, :func:`next_candidate`. At most
    ``[worlds] candidates``; the list stops after the first candidate that holds; a candidate whose status is
    None is being examined.
    """
    cands = [c for c in search.ordered_candidates(req) if c["trained"] is not None and c["trained"]["verdict"] == MET]
    out: list[dict] = []
    c = cands[0] if cands else None
    while c is not None and len(out) < search.worlds.config.candidates:
        st = world_status(search, req, c["design"])
        out.append({**c, "status": st})
        if st is None or st["holds"]:
            break
        c = next_candidate(search, req, out)
    return out


def needed_references(search) -> list[tuple[World, str]]:
    """World references the candidates being examined need and nobody simulated yet."""
    wp, out = search.worlds, []
    for req in search.requirements:
        ex = examined(search, req)
        if ex and ex[-1]["status"] is None:
            layout = search._layout(ex[-1]["design"])
            out += [(w, layout) for w in wp.worlds if (w.index, layout) not in wp.references]
    return list({(w.index, lay): (w, lay) for w, lay in out}.values())


def world_jobs(search) -> list:
    """The next evaluations of the candidates being examined: a first seed pair per world, more where undecided."""
    wp, jobs = search.worlds, []
    left = search.budget_left()
    for req in search.requirements:
        ex = examined(search, req)
        if not ex or ex[-1]["status"] is not None:
            continue
        d = ex[-1]["design"]
        for w in wp.drawn:
            wv = world_value(search, req, d, w)
            if wv is None:
                i = 0
            elif _can_extend(search, wv) and left >= 2:
                i, left = wv["runs"], left - 2
            else:
                continue
            jobs += [j for j in (_job(search, req, d, w, i), _job(search, req, d, wp.worlds[0], i)) if j is not None]
    return jobs


def worlds_table(search) -> list[dict]:
    """Per requirement, every examined candidate: worlds held, needed, verdict counts, what breaks it."""
    rows = []
    for req in search.requirements:
        for c in examined(search, req):
            st = c["status"]
            d = c["design"]
            rows.append({"requirement": req.name, "task": req.task, "key": d.key(), "design": d,
                         "cost": c["cost"], "complete": st is not None,
                         **({k: st[k] for k in ("met", "not_met", "undecided", "worlds", "needed", "holds",
                                               "breaks", "sensitivity")} if st else
                            {"met": None, "worlds": len(search.worlds.drawn), "needed": search.worlds.config.needed(),
                             "holds": False, "breaks": "not all evaluated (the run stopped)"}),
                         "per_world": [] if st is None else [
                             {"world": w.index, "parameters": w.parameters, **v}
                             for w, v in zip(search.worlds.drawn, st["per_world"])]})
    return rows
