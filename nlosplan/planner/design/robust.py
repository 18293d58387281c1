"""The worlds stage of the search: are the cheapest met candidates met in the plausible worlds?

For each requirement, its candidates whose verdict is *met* are examined
cheapest first (at most ``[worlds] candidates``): each is evaluated in every
world (:mod:`~nlosplan.planner.design.worlds`) and in world 0 (the nominal
model at the worlds' scenes) at the same seeds, and its metric in world
``w`` is its verified value shifted by the paired difference (see the worlds
module). A world's verdict is the three-valued one of that interval. Every
candidate examined first gets one seed pair per world; more seeds go, from
the worlds' own budget (``[worlds] budget``, apart from the search's so that
the per-parameter rows cannot spend it), to the examined candidate fewest
worlds short of holding (then the cheapest) among those before the first
that holds, and only to its undecided worlds that more seeds could still
turn *met* (:func:`to_extend`). The first candidate met in at least
``quorum`` of the worlds is the requirement's minimum hardware. Once a
candidate fails, the next one is not simply the next cheapest (at the requirement's margin those fail alike, and
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
from dataclasses import asdict, dataclass, field

from nlosplan.planner.design.data import SceneSet
from nlosplan.planner.design.evaluation import Evaluator, place_of
from nlosplan.planner.design.evidence import Candidate, Evidence
from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.space import Design
from nlosplan.planner.design.verdicts import (MET, NOT_MET, UNDECIDED, Z95, Verdict, metric_to_score,
                                              rank_correlation, score_to_metric, verdict, within_sd)
from nlosplan.planner.design.worlds import World, WorldsConfig

__all__ = ["WorldPlan", "WorldRun", "WorldValue", "WorldStatus", "Examined", "world_target", "world_runs",
           "needed_references", "world_value", "world_status", "attribution", "worst_loss", "next_candidate",
           "examined", "worlds_table", "flips_needed", "to_extend"]


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


@dataclass(frozen=True)
class WorldRun:
    """One evaluation the worlds stage asks for: ``design``'s ``index``-th run for ``requirement`` in ``world``."""

    requirement: Requirement
    design: Design
    world: World
    index: int


@dataclass(frozen=True)
class WorldValue:
    """A design's metric in one world: the verified value shifted by the paired world effect.

    ``seeds`` pairs finished (of ``runs`` evaluated); ``effect`` is the mean paired difference, score scale;
    ``reachable``: undecided, and more seeds of this world could still make it *met* (its centre meets the
    requirement by more than the interval's half-width would be at ``max_seeds`` pairs; the nominal design's own
    uncertainty does not shrink with the world's seeds).
    """

    value: float
    lo: float
    hi: float
    verdict: Verdict
    seeds: int
    runs: int
    effect: float
    reachable: bool = False


@dataclass(frozen=True)
class WorldStatus:
    """In how many of the drawn worlds a design is met, whether that holds, and what breaks it."""

    met: int
    not_met: int
    undecided: int
    worlds: int
    needed: int
    holds: bool
    per_world: tuple[WorldValue, ...]
    sensitivity: dict
    breaks: str
    driver: str | None = None


@dataclass(frozen=True)
class Examined:
    """A candidate examined in the worlds and its status (None while its evaluations are not all in)."""

    candidate: Candidate
    status: WorldStatus | None

    @property
    def design(self) -> Design:
        return self.candidate.design


def world_target(evidence: Evidence, w: World, layout: str) -> tuple[str | None, dict | None] | None:
    """Where world ``w``'s runs of a layout go: None until its reference exists; ``(None, None)`` for the nominal
    runs themselves (world 0 on the run's own reference); else the reference and the world's sensor overrides."""
    ref = evidence.worlds.references.get((w.index, layout))
    if ref is None:
        return None
    if w.index == 0 and str(ref) == str(evidence.trained_references.get(layout)):
        return None, None
    return str(ref), dict(w.sensor)


def _run(evidence: Evidence, req: Requirement, d: Design, w: World, i: int):
    where = world_target(evidence, w, d.layout)
    return None if where is None else evidence.run(Evaluator.TRAINED, req, d, i, place=place_of(*where))


def world_value(evidence: Evidence, req: Requirement, d: Design, w: World) -> WorldValue | None:
    """``d``'s metric in world ``w``: verified value + paired world effect, with interval and verdict."""
    nominal = evidence.trained_value(req, d)
    if nominal is None:
        return None
    control = evidence.worlds.worlds[0]
    pairs, present = [], 0
    for i in range(evidence.config.max_seeds):
        rw, r0 = _run(evidence, req, d, w, i), _run(evidence, req, d, control, i)
        if rw is None or r0 is None:
            break
        present += 1
        if rw.finite and r0.finite:
            pairs.append((rw, r0))
    if not present:
        return None
    if not pairs:  # every run failed: recorded, undecided
        return WorldValue(math.nan, math.nan, math.nan, UNDECIDED, 0, present, math.nan)
    diffs = [metric_to_score(req, a.value) - metric_to_score(req, b.value) for a, b in pairs]
    m = len(diffs)
    spread = evidence.spread(req)
    within = [s ** 2 for a, b in pairs for s in (within_sd(req, a), within_sd(req, b)) if math.isfinite(s)]
    var_within = sum(within) / len(within) if within else 0.0
    pooled = spread.var * evidence.worlds.scene_ratio if math.isfinite(spread.var) else math.nan
    if math.isfinite(pooled) and pooled >= var_within:
        from scipy.stats import t as student

        var_run, q = pooled, float(student.ppf(0.975, max(spread.dof, 1)))
    else:
        var_run, q = var_within, Z95
    centre = metric_to_score(req, nominal.value) + sum(diffs) / m
    def half_width(pairs: int) -> float:  # the nominal design's own part does not shrink with the world's pairs
        return q * math.sqrt(nominal.sd_run ** 2 / nominal.seeds + 2.0 * var_run / pairs)

    half = half_width(m)
    lo, hi = score_to_metric(req, centre - half), score_to_metric(req, centre + half)
    v = verdict(req, lo, hi)
    best_half = half_width(max(evidence.config.max_seeds, m))
    reachable = (v == UNDECIDED and present < evidence.config.max_seeds
                 and _goodness(req, score_to_metric(req, centre)) - _goodness(req, req.threshold) > best_half)
    return WorldValue(score_to_metric(req, centre), lo, hi, v, m, present, sum(diffs) / m, reachable)


def world_status(evidence: Evidence, req: Requirement, d: Design) -> WorldStatus | None:
    """In how many worlds ``d`` is met, and whether it holds, from the runs so far (None until every world has its
    first pair; more seeds of its undecided worlds come later, see :func:`world_runs`)."""
    wp = evidence.worlds
    per = [world_value(evidence, req, d, w) for w in wp.drawn]
    if any(v is None for v in per):
        return None
    met = sum(v.verdict == MET for v in per)
    sensitivity, breaks, driver = attribution(req, wp.drawn, per)
    return WorldStatus(met, sum(v.verdict == NOT_MET for v in per), sum(v.verdict == UNDECIDED for v in per),
                       len(per), wp.config.needed(), met >= wp.config.needed(), tuple(per), sensitivity, breaks,
                       driver)


def attribution(req: Requirement, worlds: list[World], per: list[WorldValue]) -> tuple[dict, str, str | None]:
    """The world parameter that ranks most closely with the margin, and where it breaks the design.

    Returns
    -------
    sensitivity : dict
        Parameter -> Spearman correlation of its values with the margin across the worlds.
    breaks : str
        What breaks the design (or that nothing does; where it stays undecided).
    driver : str or None
        The parameter blamed (None without parameters).
    """
    names = sorted({n for w in worlds for n in w.parameters})
    ok = [i for i, v in enumerate(per) if math.isfinite(v.value)]
    margins = [req.margin(per[i].value) for i in ok]
    rho = {n: rank_correlation([worlds[i].parameters.get(n, math.nan) for i in ok], margins) for n in names}
    failing = [i for i, v in enumerate(per) if v.verdict == NOT_MET]
    straddling = [i for i, v in enumerate(per) if v.verdict == UNDECIDED]
    if not names:
        return {}, "", None
    driver = max(names, key=lambda n: (abs(rho[n]), n))
    follows = f"the margin follows {driver} most (Spearman {rho[driver]:+.2f})" if abs(rho[driver]) > 0 else ""
    undecided = (f"undecided in worlds {', '.join(str(worlds[i].index) for i in straddling)} (the interval "
                 "straddles the threshold when the seeds or the budget ran out)") if straddling else ""
    if not failing:  # no world fails it: no parameter is blamed for intervals that are only too wide
        return rho, "; ".join(t for t in (undecided or "met in every world", follows) if t), driver
    vals = [worlds[i].parameters.get(driver, math.nan) for i in failing]
    worst = max(vals) if rho[driver] > 0 else min(vals)
    side = "<=" if rho[driver] > 0 else ">="
    text = (f"{driver} {side} {worst:.3g} breaks it (not met in worlds "
            f"{', '.join(str(worlds[i].index) for i in failing)}; Spearman {rho[driver]:+.2f} with the margin)"
            + (f"; {undecided}" if undecided else ""))
    return rho, text, driver


def _goodness(req: Requirement, value: float) -> float:
    """The score of a metric value oriented so that higher is better (log RMSE negated, logit accuracy)."""
    z = metric_to_score(req, value)
    return -z if req.smaller_is_better else z


def worst_loss(req: Requirement, done: list[Examined]) -> float:
    """The largest loss (score scale, >= 0) a world caused to any candidate in ``done`` (complete statuses)."""
    worst = 0.0
    for c in done:
        for v in (c.status.per_world if c.status is not None else ()):
            if math.isfinite(v.effect):
                worst = max(worst, v.effect if req.smaller_is_better else -v.effect)
    return worst


def next_candidate(evidence: Evidence, req: Requirement, done: list[Examined]) -> Candidate | None:
    """After a failed candidate: the cheapest met design whose pessimistic margin exceeds the worst world loss.

    Candidates are every design of the task verified *met* (the optimized and scanned candidates and the
    scans' trained designs) not examined yet; the margin is on the score scale, from the pessimistic end of
    the design's interval. None fit: the one with the largest margin (None when nothing is left).
    """
    seen = {c.design for c in done}
    loss = worst_loss(req, done)
    threshold = _goodness(req, req.threshold)
    pool = {c.design: c for c in evidence.candidates(req)}
    for d in evidence.trained_designs(req):
        if d not in pool:
            pool[d] = Candidate(d, evidence.cost(d), "scans, examined after a cheaper candidate failed in the worlds",
                                evidence.trained_value(req, d))
    rows = []
    for d, c in pool.items():
        tv = c.trained
        if d in seen or tv is None or tv.verdict != MET:
            continue
        rows.append((_goodness(req, tv.pessimistic(req)) - threshold, c))
    if not rows:
        return None
    robust_enough = [c for m, c in rows if m > loss]
    if robust_enough:
        return min(robust_enough, key=lambda c: (c.cost, c.design))
    return max(rows, key=lambda r: (r[0], -r[1].cost))[1]


def examined(evidence: Evidence, req: Requirement) -> list[Examined]:
    """The requirement's met candidates in the order the worlds examine them, each with its ``status``.

    The cheapest met candidate first; after a candidate that does not hold, :func:`next_candidate`. At most
    ``[worlds] candidates``; the list stops after the first candidate that holds; a candidate whose status is
    None is being examined.
    """
    cands = [c for c in evidence.candidates(req) if c.trained is not None and c.trained.verdict == MET]
    out: list[Examined] = []
    c = cands[0] if cands else None
    while c is not None and len(out) < evidence.worlds.config.candidates:
        st = world_status(evidence, req, c.design)
        out.append(Examined(c, st))
        if st is None or st.holds:
            break
        c = next_candidate(evidence, req, out)
    return out


def needed_references(evidence: Evidence) -> list[tuple[World, str]]:
    """World references the candidates being examined need and nobody simulated yet."""
    wp, out = evidence.worlds, []
    for req in evidence.requirements:
        ex = examined(evidence, req)
        if ex and ex[-1].status is None:
            layout = ex[-1].design.layout
            out += [(w, layout) for w in wp.worlds if (w.index, layout) not in wp.references]
    return list({(w.index, lay): (w, lay) for w, lay in out}.values())


def flips_needed(st: WorldStatus) -> int | None:
    """Undecided worlds that must turn *met* for the design to hold; None when it cannot (too few reachable)."""
    need = max(0, st.needed - st.met)
    reachable = sum(v.reachable for v in st.per_world)
    return need if need <= reachable else None


def to_extend(ex: list[Examined], pairs: int) -> Examined | None:
    """The candidate of ``ex`` (:func:`examined`) whose undecided worlds get the next seeds, or None.

    Only candidates examined before the first that holds (a cheaper answer, if they hold), that could still hold
    (:func:`flips_needed`) with at most ``pairs`` more seed pairs: the one fewest worlds short of holding, then the
    cheapest. So the worlds' budget goes where a seed can change the answer, not to a candidate at the
    requirement's margin that would need every world decided.
    """
    options = []
    for e in ex:
        if e.status is None:
            return None
        if e.status.holds:
            break
        n = flips_needed(e.status)
        if n is not None and 0 < n <= pairs:
            options.append((n, e.candidate.cost, e.design, e))
    return min(options, key=lambda o: o[:3])[3] if options else None


def world_runs(evidence: Evidence) -> list[WorldRun]:
    """The next evaluations of the worlds stage: a first seed pair per world (the world's run and the control's)
    for the candidate being examined; once every examined candidate has its first pairs, one more pair for each
    reachable undecided world of :func:`to_extend`'s candidate while ``[worlds] budget`` lasts."""
    wp, runs = evidence.worlds, []
    left = evidence.worlds_budget_left()
    for req in evidence.requirements:
        ex = examined(evidence, req)
        if not ex:
            continue
        if ex[-1].status is None:
            d = ex[-1].design
            for w in wp.drawn:
                if world_value(evidence, req, d, w) is None:
                    runs += [WorldRun(req, d, w, 0), WorldRun(req, d, wp.worlds[0], 0)]
            continue
        pick = to_extend(ex, left // 2)
        if pick is None:
            continue
        for w, wv in zip(wp.drawn, pick.status.per_world):
            if wv.reachable and left >= 2:
                runs += [WorldRun(req, pick.design, w, wv.runs), WorldRun(req, pick.design, wp.worlds[0], wv.runs)]
                left -= 2
    return runs


def worlds_table(evidence: Evidence) -> list[dict]:
    """Per requirement, every examined candidate: worlds held, needed, verdict counts, what breaks it."""
    rows = []
    wp = evidence.worlds
    for req in evidence.requirements:
        for c in examined(evidence, req):
            st, d = c.status, c.design
            counts = ({"met": st.met, "not_met": st.not_met, "undecided": st.undecided, "worlds": st.worlds,
                       "needed": st.needed, "holds": st.holds, "breaks": st.breaks, "sensitivity": st.sensitivity}
                      if st else {"met": None, "worlds": len(wp.drawn), "needed": wp.config.needed(), "holds": False,
                                  "breaks": "not all evaluated (the run stopped)"})
            rows.append({"requirement": req.name, "task": req.task, "key": d.key(), "design": d,
                         "cost": c.candidate.cost, "complete": st is not None, **counts,
                         "per_world": [] if st is None else [{"world": w.index, "parameters": w.parameters,
                                                              **asdict(v)} for w, v in zip(wp.drawn, st.per_world)]})
    return rows
