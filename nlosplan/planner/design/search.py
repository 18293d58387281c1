"""The multi-fidelity design search, as ask/tell (:class:`~nlosplan.planner.protocol.AskTellPlanner`).

:class:`DesignSearch` proposes batches of evaluations (:meth:`~DesignSearch.suggest`)
and takes their results (:meth:`~DesignSearch.ingest`); it never runs anything
itself, so the same search runs serially, on a process pool or on Dask, and
resumes from a log of results (anything already ingested is not suggested
again). Stages:

1. **screen** — the fast bounds (CRLB, ideal observer) on one-at-a-time grids
   along every axis from the reference design, and along jitter and photon
   budget for every zone layout (the trade-off curves).
2. **learners** — every candidate model (``models``: MLP and 1D CNN by
   default) trained on the reference design over ``seeds`` seeds; the best
   of each task is its *learner*, used for every trained evaluation after.
3. **curves** — the learner at the grid points whose bound meets the
   requirement (a design that fails its bound fails every model: it is
   recorded as screened out, not trained). Along the axes the metric is
   monotone in (:data:`MONOTONE`) a line is trained from its costliest end,
   and stops where the learner's verdict is *not met*: every cheaper design
   of the line fails too (recorded as implied, not trained).
4. **refine** — bisection on the continuous axes (jitter, pulse, photons) and bins,
   between the last grid point that meets a requirement and the first that
   does not (the metric is monotone in them), ``refine_steps`` times.
5. **optimize** — for every discrete choice (zones x bin width) and task,
   nlopt COBYLA over normalized continuous variables (jitter, log photons,
   bins) minimizes the cost subject to the bound corrected by the
   bound-to-trained gap measured in stages 1-4 (multi-fidelity).
6. **verify** — the cheapest candidates per requirement (optimized, and the
   cheapest scanned designs not already failed) over ``seeds`` seeds.
7. **decide** — the cheapest candidate whose verdict is *undecided*
   (:mod:`~nlosplan.planner.design.verdicts`) gets one more seed (new noise,
   split and training seed) per round, until it is decided, reaches
   ``max_seeds`` or the run's ``budget`` of extra evaluations is spent.
8. **worlds** — the cheapest met candidates in the plausible worlds
   (:mod:`~nlosplan.planner.design.worlds`, :mod:`~nlosplan.planner.design.robust`).

Seeds: evaluation ``i`` of a design uses seed ``seed * 1000 + i`` (``seed``:
the run's ``--seed``), so two runs with different seeds draw new noise, new
splits and new training seeds everywhere.
"""

from __future__ import annotations

import json
import math

import numpy as np

from nlosplan.planner.design.cost import CostModel
from nlosplan.planner.design.jobs import DesignJob
from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.search_config import DEFAULT_MODELS, MAX_SEED, SEED_STRIDE, SearchConfig
from nlosplan.planner.design.space import Design, DesignSpace
from nlosplan.planner.design.verdicts import (MET, NOT_MET, UNDECIDED, Spread, metric_to_score, pooled_spread,
                                              score_to_metric, seed_interval, verdict)

__all__ = ["SearchConfig", "DesignSearch", "axis_grid", "CONTINUOUS", "MORE_IS_BETTER", "metric_to_score",
           "score_to_metric", "MAX_SEED", "SEED_STRIDE", "DEFAULT_MODELS"]

CONTINUOUS = ("jitter_fwhm_ps", "pulse_fwhm_ps", "photon_fraction")
#: Axes along which a larger value is more (better, costlier) hardware.
MORE_IS_BETTER = {"zones": True, "bin_factor": False, "n_bins": True, "jitter_fwhm_ps": False,
                  "pulse_fwhm_ps": False, "photon_fraction": True}
_CURVE_AXES = ("jitter_fwhm_ps", "photon_fraction")  # also per zone layout
#: Axes the learner's metric is taken to be monotone in (bisection; implied verdicts on the curves).
MONOTONE = CONTINUOUS + ("n_bins",)


def axis_grid(space: DesignSpace, axis: str, points: int, base: Design) -> list[Design]:
    """Designs along one axis from ``base`` (others fixed), cheapest to costliest order not implied."""
    if axis == "zones":
        return [base.replace(zones=z) for z in space.zones]
    if axis == "bin_factor":  # same window: bins shrink as they widen
        return [base.replace(bin_factor=f, n_bins=max(1, min(space.max_bins(f), base.n_bins * 1 // f)))
                for f in space.bin_factors]
    if axis == "n_bins":
        lo, hi = space.n_bins[0], space.max_bins(base.bin_factor)
        vals = sorted({int(round(v)) for v in np.linspace(lo, hi, points)})
        return [base.replace(n_bins=v) for v in vals]
    lo, hi = getattr(space, axis)
    if axis == "photon_fraction":
        vals = np.geomspace(lo, hi, points)
    else:
        vals = np.linspace(lo, hi, points)
    return [base.replace(**{axis: float(round(v, 6))}) for v in vals]


def _met(req: Requirement, value: float) -> bool:
    return math.isfinite(value) and req.met(value)


class DesignSearch:
    """Ask/tell design search over a space, for a set of requirements.

    Parameters
    ----------
    space : DesignSpace
    requirements : sequence of Requirement
    config : SearchConfig
    references : dict
        Zone layout ``"RxC"`` -> path of its saved reference data (simulated).
    cost : CostModel
    trained_references : dict, optional
        Zone layout -> reference of real captures for the trained evaluator
        (default: the simulated ``references``).
    worlds : WorldPlan, optional
        The plausible worlds to check the cheapest met candidates in
        (:class:`~nlosplan.planner.design.robust.WorldPlan`); none: no worlds stage.
    """

    STAGES = ("screen", "learners", "curves", "refine", "optimize", "verify", "decide", "worlds", "done")

    def __init__(self, space: DesignSpace, requirements, config: SearchConfig, references: dict,
                 cost: CostModel | None = None, trained_references: dict | None = None, worlds=None):
        self.space, self.requirements, self.config = space, list(requirements), config
        self.references = dict(references)
        self.trained_references = dict(trained_references or references)
        self.cost = cost or CostModel()
        self.base = space.reference_design()
        self.results: dict[str, dict] = {}
        self.stage = "screen"
        self._optimized = False
        self.candidates: dict[str, list[dict]] = {}
        self.optimize_log: list[dict] = []
        self.worlds = worlds
        self._learners: dict[str, str] = {}
        self._version = 0
        self._spreads: dict = {}

    # ---------------------------------------------------------------- jobs
    def _layout(self, d: Design) -> str:
        return f"{d.zones[0]}x{d.zones[1]}"

    def job(self, evaluator: str, req: Requirement, d: Design, seed: int = 0, *, model: str | None = None,
            reference: str | None = None, world: dict | None = None) -> DesignJob:
        """The job of ``d``'s ``seed``-th run (an index: the evaluation seed is :meth:`SearchConfig.seed_of` it).

        Trained jobs use ``model`` (default: the task's learner); ``reference`` and ``world`` place the job
        in a world (see :mod:`~nlosplan.planner.design.robust`).
        """
        refs = self.trained_references if evaluator == "trained" else self.references
        fid = self.config.fidelity["trained" if evaluator == "trained_sim" else evaluator]
        if evaluator != "bound":
            fid = {**fid, "model": model or self.learner(req.task)}
        elif req.task != "loc" and int(fid.get("looks", 1)) > 1:  # the observer stops once clear of every threshold
            fid = {**fid, "stop_at": sorted({r.threshold for r in self.requirements
                                             if r.task == req.task and str(r.condition) == str(req.condition)})}
        return DesignJob(evaluator, req.task, d, self.config.seed_of(seed), fid, req.condition,
                         str(reference or refs[self._layout(d)]), self.space.sensor.to_dict(), world)

    def result(self, evaluator: str, req: Requirement, d: Design, seed: int = 0) -> dict | None:
        return self.results.get(self.job(evaluator, req, d, seed).key)

    def lines(self) -> list[tuple[str, str, Design, list[Design]]]:
        """The one-at-a-time lines: (axis, layout label, base, designs)."""
        out = []
        for axis in self.space.axes:
            out.append((axis, self._layout(self.base), self.base,
                        axis_grid(self.space, axis, self.config.grid_points, self.base)))
        for z in self.space.zones:
            if z == self.base.zones:
                continue
            b = self.base.replace(zones=z)
            for axis in _CURVE_AXES:
                if axis in self.space.axes:
                    out.append((axis, self._layout(b), b, axis_grid(self.space, axis, self.config.grid_points, b)))
        return out

    def _line_designs(self) -> list[Design]:
        return list(dict.fromkeys(d for *_, ds in self.lines() for d in ds))

    # ----------------------------------------------------------- ask / tell
    def ingest(self, results) -> None:
        """Record evaluation results (ok, unreachable or failed), in order."""
        for result in results:
            self.results[result["key"]] = result
            self._version += 1

    def _new(self, jobs: list[DesignJob]) -> list[DesignJob]:
        seen, out = set(), []
        for j in jobs:
            key = j.key
            if key not in self.results and key not in seen:
                seen.add(key)
                out.append(j)
        return out

    def suggest(self, n: int | None = None) -> list[DesignJob]:
        """The next batch of evaluations, at most ``n`` (all of the stage's by default; empty: finished).

        Stages advance when everything they suggested has been ingested; jobs
        already ingested (a resumed run) are never suggested again.
        """
        while True:
            jobs = self._new(self._stage_jobs())
            if jobs:
                return jobs if n is None else jobs[:n]
            if not self._advance():
                return []

    def _stage_jobs(self) -> list[DesignJob]:
        from nlosplan.planner.design import robust

        if self.stage == "screen":
            return [self.job("bound", r, d) for r in self.requirements for d in self._line_designs()]
        if self.stage == "learners":
            return [self.job("trained", r, self.base, s, model=m) for r in self._task_requirements()
                    for m in self.config.models for s in range(self.config.seeds)]
        if self.stage == "curves":
            return self._curve_jobs()
        if self.stage == "refine":
            return self._refine_jobs()
        if self.stage == "verify":
            jobs = [self.job("trained", r, c["design"], s) for r in self.requirements
                    for c in self.candidates.get(r.name, []) for s in range(self.config.seeds)]
            if self.has_real:  # the same designs trained on simulated captures: where do sim and real disagree?
                jobs += [self.job("trained_sim", r, d) for r in self.requirements for d in self.trained_designs(r)]
            return jobs
        if self.stage == "decide":
            return self._decide_jobs()
        if self.stage == "worlds" and self.worlds is not None:
            return robust.world_jobs(self)
        return []

    def _advance(self) -> bool:
        from nlosplan.planner.design import robust

        if self.stage == "done" or (self.stage == "optimize" and not self._optimized):
            return False  # optimize runs in the driver (see run.py), which then calls set_candidates
        if self.stage == "worlds" and self.worlds is not None and robust.needed_references(self):
            return False  # the driver simulates the worlds' references, then calls add_world_references
        self.stage = self.STAGES[self.STAGES.index(self.stage) + 1]
        return True

    # ------------------------------------------------------------- learners
    def _task_requirements(self) -> list[Requirement]:
        """The first requirement of each task (its condition is the one learners are compared on)."""
        return list({r.task: r for r in reversed(self.requirements)}.values())[::-1]

    def learner(self, task: str) -> str:
        """The task's learner: the candidate model with the best mean metric on the reference design.

        Until every candidate has run its seeds there, the first of ``models``.
        """
        if task in self._learners:
            return self._learners[task]
        models = self.config.models
        req = next((r for r in self._task_requirements() if r.task == task), None)
        if len(models) == 1 or req is None:
            return models[0]
        means = {}
        for m in models:
            recs = [self.results.get(self.job("trained", req, self.base, s, model=m).key)
                    for s in range(self.config.seeds)]
            if any(r is None for r in recs):
                return models[0]
            vals = [r["value"] for r in recs if r["status"] == "ok" and math.isfinite(r["value"])]
            if vals:
                means[m] = float(np.mean(vals))
        best = models[0] if not means else min(means, key=lambda m: (means[m] if req.smaller_is_better
                                                                      else -means[m], models.index(m)))
        self._learners[task] = best
        return best

    def learner_table(self) -> list[dict]:
        """Every candidate model on the reference design, per task: mean metric, interval, seconds, chosen."""
        rows = []
        for req in self._task_requirements():
            chosen = self.learner(req.task)
            for m in self.config.models:
                recs = [self.results.get(self.job("trained", req, self.base, s, model=m).key)
                        for s in range(self.config.max_seeds)]
                tv = seed_interval(req, [r for r in recs if r is not None], self.spread(req))
                rows.append({"task": req.task, "requirement": req.name, "model": m, "chosen": m == chosen,
                             **({"value": tv["value"], "lo": tv["lo"], "hi": tv["hi"], "seeds": tv["seeds"],
                                 "seconds_per_run": tv["seconds"] / tv["seeds"]} if tv else
                                {"value": None, "lo": None, "hi": None, "seeds": 0, "seconds_per_run": None})})
        return rows

    # --------------------------------------------------------------- stages
    @property
    def has_real(self) -> bool:
        """The trained evaluator reads real captures (and ``trained_sim`` the simulated ones)."""
        return self.trained_references != self.references

    def trained_designs(self, req: Requirement) -> list[Design]:
        """Designs with a successful trained evaluation for ``req``'s task (nominal model)."""
        return sorted({Design.from_dict(r["design"]) for r in self.results.values()
                       if r["task"] == req.task and r["evaluator"] == "trained" and r["status"] == "ok"
                       and r.get("world") is None})

    def disagreements(self, req: Requirement) -> list[dict]:
        """Real against simulated trained metrics of the same designs (real backend only).

        ``disagree`` is True where their 95 % intervals do not overlap.
        """
        rows = []
        for d in self.trained_designs(req):
            real, sim = self.trained_value(req, d), self.result("trained_sim", req, d)
            if real is None or sim is None or sim["status"] != "ok":
                continue
            rows.append({"requirement": req.name, "design": d.key(), "real": real["value"], "real_lo": real["lo"],
                         "real_hi": real["hi"], "sim": sim["value"], "sim_lo": sim["lo"], "sim_hi": sim["hi"],
                         "disagree": bool(real["hi"] < sim["lo"] or sim["hi"] < real["lo"])})
        return rows

    def bound_meets(self, req: Requirement, d: Design) -> bool:
        """Does the design's bound meet the requirement (optimistic side of its interval)?"""
        r = self.result("bound", req, d)
        if r is None or r["status"] != "ok":
            return r is not None and r["status"] == "failed"  # a failed bound does not screen out
        best = r["lo"] if req.smaller_is_better else r["hi"]
        return _met(req, best)

    def spread(self, req: Requirement) -> Spread:
        """The run-to-run variance of the requirement's metric (the learner's, nominal model), pooled over designs."""
        key = (req.task, str(req.condition), self._version)
        if key not in self._spreads:
            groups: dict = {}
            model, cond = self.learner(req.task), None if req.condition is None else str(req.condition)
            for r in self.results.values():
                if (r["evaluator"] == "trained" and r["task"] == req.task and r.get("world") is None
                        and r.get("condition") == cond and r["fidelity"].get("model") == model
                        and r["status"] == "ok"):
                    groups.setdefault(json.dumps(r["design"], sort_keys=True), []).append(r["value"])
            self._spreads = {k: v for k, v in self._spreads.items() if k[2] == self._version}
            self._spreads[key] = pooled_spread(req, groups.values())
        return self._spreads[key]

    def runs(self, req: Requirement, d: Design, evaluator: str = "trained") -> list[dict]:
        """The learner's finished runs of ``d`` (nominal model), in seed order."""
        out = []
        for s in range(self.config.max_seeds):
            r = self.results.get(self.job(evaluator, req, d, s).key)
            if r is not None:
                out.append(r)
        return out

    def trained_value(self, req: Requirement, d: Design) -> dict | None:
        """Mean trained metric over the seeds run, with the 95 % interval of that mean and its ``verdict``.

        See :func:`~nlosplan.planner.design.verdicts.seed_interval` (None if never trained).
        """
        tv = seed_interval(req, self.runs(req, d), self.spread(req))
        if tv is not None:
            tv["verdict"] = verdict(req, tv["lo"], tv["hi"])
        return tv

    def _curve_jobs(self) -> list[DesignJob]:
        """Trained jobs of the curves: every bound-passing point of a line, or on a monotone axis the costliest
        point not yet trained, until one is not met (one per line and round)."""
        jobs = []
        for req in self.requirements:
            for axis, _, _, designs in self.lines():
                pts = [d for d in designs if self.bound_meets(req, d)]
                if axis not in MONOTONE:
                    jobs += [self.job("trained", req, d) for d in pts]
                    continue
                for d in sorted(pts, key=lambda d: d.value(axis, self.space.sensor), reverse=MORE_IS_BETTER[axis]):
                    tv = self.trained_value(req, d)
                    if tv is None:
                        jobs.append(self.job("trained", req, d))
                        break
                    if tv["verdict"] == NOT_MET:
                        break
        return jobs

    def _refine_jobs(self) -> list[DesignJob]:
        jobs = []
        for req in self.requirements:
            for axis, layout, base, designs in self.lines():
                if (axis not in CONTINUOUS and axis != "n_bins") or layout != self._layout(self.base):
                    continue
                pts = self.line_points(req, axis, base)
                grid = set(designs)
                if sum(p["design"] not in grid and (p["trained"] is not None or p["screened"] or p["implied"])
                       for p in pts) >= self.config.refine_steps:
                    continue
                bracket = _bracket(pts, req, MORE_IS_BETTER[axis])
                if bracket is None:
                    continue
                a, b = bracket
                if axis == "n_bins":  # whole bins: stop when the bracket is one bin wide
                    mid = int(round(0.5 * (a + b)))
                    if mid in (int(a), int(b)):
                        continue
                    d = base.replace(n_bins=mid)
                else:
                    mid = math.sqrt(a * b) if axis == "photon_fraction" else 0.5 * (a + b)
                    d = base.replace(**{axis: float(round(mid, 6))})
                if self.bound_meets(req, d) or self.result("bound", req, d) is None:
                    if self.result("bound", req, d) is None:
                        jobs.append(self.job("bound", req, d))
                    else:
                        jobs.append(self.job("trained", req, d))
        return jobs

    # --------------------------------------------------------------- decide
    def extra_spent(self) -> int:
        """Extra evaluations spent deciding (seeds beyond ``seeds`` in the nominal model, beyond 1 in worlds)."""
        n, base = 0, self.config.seed_of(0)
        for r in self.results.values():
            if r["evaluator"] == "trained":
                i = r["seed"] - base
                n += i >= (1 if r.get("world") is not None else self.config.seeds)
        return n

    def budget_left(self) -> int:
        return max(0, self.config.budget - self.extra_spent())

    def ordered_candidates(self, req: Requirement) -> list[dict]:
        """The requirement's candidates, cheapest first, each with ``cost`` and ``trained`` (its value or None)."""
        out = []
        for c in self.candidates.get(req.name, []):
            d = c["design"]
            out.append({**c, "cost": self.cost(d, self.space), "trained": self.trained_value(req, d)})
        return sorted(out, key=lambda c: (c["cost"], c["design"]))

    def _decide_jobs(self) -> list[DesignJob]:
        jobs, left = [], self.budget_left()
        for req in self.requirements:
            for c in self.ordered_candidates(req):
                tv = c["trained"]
                if tv is not None and tv["verdict"] == MET:
                    break
                if tv is not None and tv["verdict"] == UNDECIDED:
                    if tv["seeds"] < self.config.max_seeds and len(jobs) < left:
                        jobs.append(self.job("trained", req, c["design"], len(self.runs(req, c["design"]))))
                    break  # one per requirement and round: the cheapest undecided
        return jobs

    def decision(self, req: Requirement, tv: dict | None) -> str:
        """Why a verified candidate's verdict stands: decided, or undecided and which limit stopped it."""
        if tv is None:
            return "not evaluated"
        if tv["verdict"] != UNDECIDED:
            return f"{tv['verdict']} after {tv['seeds']} seed(s)"
        if tv["seeds"] >= self.config.max_seeds:
            return f"undecided after {tv['seeds']} seeds: max_seeds ({self.config.max_seeds}) reached"
        if self.budget_left() <= 0:
            return (f"undecided after {tv['seeds']} seed(s): the budget of {self.config.budget} extra evaluations "
                    "is spent")
        if self.stage in ("decide", "worlds", "done"):
            return f"undecided after {tv['seeds']} seed(s): a cheaper candidate was decided met first"
        return f"undecided after {tv['seeds']} seed(s): the run stopped before the decide stage"

    def scan_candidates(self, req: Requirement, n: int) -> list[dict]:
        """The ``n`` cheapest scanned designs whose mean meets ``req``, and the cheapest met one if not among them.

        When no mean meets it, the undecided design closest to meeting it (so that seeds can decide it).
        """
        rows, undecided = [], []
        for d in self.trained_designs(req):
            tv = self.trained_value(req, d)
            if tv is None:
                continue
            if req.met(tv["value"]):
                rows.append((self.cost(d, self.space), d, tv["verdict"]))
            elif tv["verdict"] == UNDECIDED:
                undecided.append((-req.margin(tv["value"]), self.cost(d, self.space), d))
        rows.sort(key=lambda r: (r[0], r[1]))
        picked = [(c, d) for c, d, _ in rows[:n]] + [(c, d) for c, d, v in rows[n:] if v == MET][:1]
        if not rows and undecided:
            _, c, d = min(undecided, key=lambda u: (u[0], u[1], u[2]))
            picked = [(c, d)]
        return [{"design": d, "cost": c, "source": "scans"} for c, d in picked]

    def line_points(self, req: Requirement, axis: str, base: Design) -> list[dict]:
        """Every evaluated design on the line through ``base`` along ``axis``, sorted by the axis value.

        Each point: ``x`` (axis value in its unit), ``design``, ``bound`` (value or None),
        ``trained`` (:meth:`trained_value` or None), ``screened`` (the bound failed), ``implied`` (not
        trained: a costlier design of the line, on a :data:`MONOTONE` axis, is not met).
        """
        pts = {}
        for r in self.results.values():
            if r["task"] != req.task or r.get("condition") != (None if req.condition is None else str(req.condition)):
                continue
            d = Design.from_dict(r["design"])
            if any(getattr(d, f) != getattr(base, f) for f in ("zones", "bin_factor", "n_bins", "jitter_fwhm_ps",
                                                                "pulse_fwhm_ps", "photon_fraction")
                   if f != axis and not (axis == "bin_factor" and f == "n_bins")):
                continue
            if axis == "bin_factor" and d.n_bins != max(1, min(self.space.max_bins(d.bin_factor), base.n_bins // d.bin_factor)):
                continue
            if d in pts:
                continue
            bound = self.result("bound", req, d)
            pts[d] = {"x": d.value(axis, self.space.sensor), "design": d,
                      "bound": None if bound is None or bound["status"] != "ok" else bound["value"],
                      "bound_status": None if bound is None else bound["status"],
                      "bound_reason": "" if bound is None else bound["reason"],
                      "trained": self.trained_value(req, d),
                      "screened": bound is not None and bound["status"] == "ok" and not self.bound_meets(req, d)}
        out = sorted(pts.values(), key=lambda p: p["x"])
        failed = [p["x"] for p in out if p["trained"] is not None and p["trained"]["verdict"] == NOT_MET]
        for p in out:
            p["implied"] = (axis in MONOTONE and p["trained"] is None and not p["screened"] and any(
                (x > p["x"]) == MORE_IS_BETTER[axis] and x != p["x"] for x in failed))
        return out

    # ------------------------------------------------------- multi-fidelity
    def gap(self, req: Requirement) -> dict:
        """The bound-to-trained gap of a task over every design evaluated by both.

        Localization: the median log ratio trained / bound; accuracies: the
        median logit difference. ``n`` pairs, and ``spread`` (their IQR).
        """
        diffs = []
        for d in {Design.from_dict(r["design"]) for r in self.results.values() if r["task"] == req.task}:
            b, t = self.result("bound", req, d), self.trained_value(req, d)
            if b is None or t is None or b["status"] != "ok" or not math.isfinite(b["value"]):
                continue
            diffs.append(metric_to_score(req, t["value"]) - metric_to_score(req, b["value"]))
        if not diffs:
            return {"value": 0.0, "n": 0, "spread": math.nan}
        q1, med, q3 = np.percentile(diffs, [25, 50, 75])
        return {"value": float(med), "n": len(diffs), "spread": float(q3 - q1)}

    def predict(self, req: Requirement, bound_value: float) -> float:
        """The trained metric predicted from a bound value and the measured gap."""
        return score_to_metric(req, metric_to_score(req, bound_value) + self.gap(req)["value"])

    def set_candidates(self, candidates: dict[str, list[dict]], log: list[dict]) -> None:
        """Candidates per requirement name from the optimize stage (see :func:`optimize.run_optimize`)."""
        self.candidates = candidates
        self.optimize_log = log
        self._optimized = True

    def add_world_references(self, paths: dict) -> None:
        """``(world index, layout) -> path`` of simulated world references (see :mod:`.robust`)."""
        self.worlds.references.update(paths)


def _bracket(points: list[dict], req: Requirement, more_is_better: bool):
    """Adjacent axis values (meets, misses) by the trained metric, or None."""
    seq = [p for p in points if p["trained"] is not None or p["screened"] or p.get("implied")]
    if not more_is_better:
        seq = seq[::-1]  # walk from the cheapest end (more jitter) to the costliest
    # now: along seq hardware increases; find the first index that meets
    for i in range(1, len(seq)):
        prev_ok = seq[i - 1]["trained"] is not None and _met(req, seq[i - 1]["trained"]["value"])
        cur_ok = seq[i]["trained"] is not None and _met(req, seq[i]["trained"]["value"])
        if cur_ok and not prev_ok:
            a, b = seq[i]["x"], seq[i - 1]["x"]
            if abs(a - b) <= 1e-6 * max(abs(a), abs(b), 1.0):
                return None
            return a, b
    return None
