"""The multi-fidelity design search: an ask/tell stage machine (:class:`~nlosplan.planner.protocol.AskTellPlanner`).

:class:`DesignSearch` proposes batches of evaluations (:meth:`~DesignSearch.suggest`) and takes their results
(:meth:`~DesignSearch.ingest`); it never runs anything itself, so the same search runs serially, on a process
pool or on Dask, and resumes from a log of results (anything already ingested is not suggested again). What it
learns is kept in a typed evidence store whose read-only face, :attr:`~DesignSearch.evidence`
(:class:`~nlosplan.planner.design.evidence.Evidence`), is all its neighbours read. Stages (:class:`Stage`):

1. **screen** — the fast bounds (CRLB, ideal observer) on one-at-a-time grids along every axis from the
   reference design, and along jitter and photon budget for every zone layout (the trade-off curves,
   :mod:`~nlosplan.planner.design.lines`).
2. **learners** — every candidate model (``models``: MLP, 1D CNN and knn by default) trained on the reference
   design at one seed, then those still in contention over ``seeds`` seeds; the best of each task is its *learner*.
3. **curves** — the learner at the grid points whose bound meets the requirement (a design that fails its bound
   fails every model: it is recorded as screened out, not trained). Along the axes the metric is monotone in
   (:data:`~nlosplan.planner.design.lines.MONOTONE`) a line is trained from its costliest end, and stops where
   the learner's verdict is *not met*: every cheaper design of the line fails too (recorded as implied); and the
   learner's learning curve at the reference design (:mod:`~nlosplan.planner.design.learning_curve`).
4. **refine** — bisection on the continuous axes (jitter, pulse, photons) and bins, between the last grid point
   that meets a requirement and the first that does not, ``refine_steps`` times.
5. **optimize** — for every discrete choice (zones x bin width) and task, nlopt COBYLA over normalized continuous
   variables minimizes the cost subject to the bound corrected by the bound-to-trained gap measured in stages
   1-4 (multi-fidelity). The driver runs :meth:`~DesignSearch.optimize_jobs` and hands back the candidates
   (:meth:`~DesignSearch.ingest_candidates`).
6. **verify** — the cheapest candidates per requirement (optimized, and the cheapest scanned designs not
   already failed) over ``seeds`` seeds.
7. **decide** — the cheapest *undecided* candidate (:mod:`~nlosplan.planner.design.verdicts`), then the design
   deciding each undecided per-parameter row, get one more seed (new noise, split and training seed) per round,
   until decided, at ``max_seeds``, or the run's ``budget`` of extra evaluations is spent.
8. **worlds** — the cheapest met candidates in the plausible worlds (:mod:`~nlosplan.planner.design.robust`);
   the driver simulates the worlds' references the search names (:meth:`~DesignSearch.needed_references`,
   :meth:`~DesignSearch.ingest_references`).

Adding a stage is a member of :class:`Stage` and the method that makes its jobs, listed in ``_stage_jobs``.
Seeds: evaluation ``i`` of a design uses seed ``seed * 1000 + i`` (``seed``: the run's ``--seed``), so two runs
with different seeds draw new noise, new splits and new training seeds everywhere.
"""

from __future__ import annotations

import math
from enum import StrEnum

from nlosplan.planner.design import robust
from nlosplan.planner.design.cost import CostModel
from nlosplan.planner.design.evaluation import Evaluation, Evaluator
from nlosplan.planner.design.evidence import Candidate, Evidence, EvidenceStore
from nlosplan.planner.design.jobs import DesignJob, OptimizeJob
from nlosplan.planner.design.learning_curve import curve_runs, undecided_target_runs, with_budget
from nlosplan.planner.design.lines import MONOTONE, MORE_IS_BETTER, bracket, line_points, lines, undecided_lines
from nlosplan.planner.design.optimize import optimize_jobs
from nlosplan.planner.design.requirements import Requirement, Task
from nlosplan.planner.design.search_config import DEFAULT_MODELS, MAX_SEED, SEED_STRIDE, SearchConfig
from nlosplan.planner.design.space import Design, DesignSpace
from nlosplan.planner.design.verdicts import MET, NOT_MET, UNDECIDED

__all__ = ["DesignSearch", "Stage", "SearchConfig", "MAX_SEED", "SEED_STRIDE", "DEFAULT_MODELS"]


class Stage(StrEnum):
    """The search's stages, in run order (a member is its name, as progress and logs show it)."""

    SCREEN = "screen"
    LEARNERS = "learners"
    CURVES = "curves"
    REFINE = "refine"
    OPTIMIZE = "optimize"
    VERIFY = "verify"
    DECIDE = "decide"
    WORLDS = "worlds"
    DONE = "done"

    def after(self, other: "Stage") -> bool:
        """Whether this stage comes after ``other``."""
        return list(Stage).index(self) > list(Stage).index(other)


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
        Zone layout -> reference of real captures for the trained evaluators (default: the simulated ones).
    worlds : WorldPlan, optional
        The plausible worlds to check the cheapest met candidates in
        (:class:`~nlosplan.planner.design.robust.WorldPlan`); none: no worlds stage.
    """

    def __init__(self, space: DesignSpace, requirements, config: SearchConfig, references: dict,
                 cost: CostModel | None = None, trained_references: dict | None = None, worlds=None):
        sims, trained = dict(references), dict(trained_references or references)
        self._refs = {Evaluator.BOUND: sims, Evaluator.TRAINED: trained, Evaluator.TRAINED_SIM: sims,
                      Evaluator.LEARNING_CURVE: trained}
        self._store = EvidenceStore()
        self._ev = Evidence(self._store, space, requirements, config, cost or CostModel(), worlds, trained,
                            has_real=trained != sims)
        self._lines = lines(space, self._ev.base, config.grid_points)
        self._stage = Stage.SCREEN
        self._optimized = False

    @property
    def stage(self) -> Stage:
        """The stage whose evaluations :meth:`suggest` proposes (or that waits for its driver)."""
        return self._stage

    @property
    def evidence(self) -> Evidence:
        """Everything ingested so far, read-only (what the summary, the worlds and the progress page read)."""
        return self._ev

    # ---------------------------------------------------------------- jobs
    def job(self, evaluator: Evaluator | str, req: Requirement, d: Design, seed: int = 0, *,
            model: str | None = None, reference: str | None = None, world: dict | None = None) -> DesignJob:
        """The job of ``d``'s ``seed``-th run (an index: the evaluation seed is :meth:`SearchConfig.seed_of` it).

        A learner's job uses ``model`` (default: the task's learner); ``reference`` and ``world`` place the
        job in a world (see :mod:`~nlosplan.planner.design.robust`).
        """
        evaluator, ev = Evaluator(evaluator), self._ev
        fid = ev.config.fidelity[evaluator.knobs]
        if evaluator.trains:
            fid = {**fid, "model": model or ev.learner(req.task)}
        elif req.task is not Task.LOC and int(fid.get("looks", 1)) > 1:  # the observer stops once clear of them all
            fid = {**fid, "stop_at": sorted({r.threshold for r in ev.requirements
                                             if r.task == req.task and r.condition == req.condition})}
        return DesignJob(evaluator, req.task, d, ev.config.seed_of(seed), fid, req.condition,
                         str(reference or self._refs[evaluator][d.layout]), ev.space.sensor.to_dict(), world)

    def optimize_jobs(self) -> list[OptimizeJob]:
        """The optimize stage's runs, one per requirement and discrete choice (:mod:`.optimize`)."""
        return optimize_jobs(self._ev, lambda req, d: self.job(Evaluator.BOUND, req, d))

    def needed_references(self) -> list:
        """World references the worlds stage waits for: ``(World, layout)`` pairs nobody simulated yet."""
        return [] if self._ev.worlds is None else robust.needed_references(self._ev)

    # ----------------------------------------------------------- ask / tell
    def ingest(self, results) -> None:
        """Record evaluation results (ok, unreachable or failed; records or result dicts), in order."""
        for r in results:
            self._store.add(r if isinstance(r, Evaluation) else Evaluation.from_record(r))

    def ingest_candidates(self, candidates: dict[str, list[Candidate]], log: list[dict]) -> None:
        """The optimize stage's candidates per requirement name (:func:`~.optimize.collect_candidates`) and its
        result rows; the stages before it are over (a resumed run continues from there)."""
        self._store.set_candidates(candidates, log)
        self._optimized = True
        if Stage.OPTIMIZE.after(self._stage):
            self._set_stage(Stage.OPTIMIZE)

    def ingest_references(self, paths: dict) -> None:
        """``(world index, layout) -> path`` of simulated world references (see :meth:`needed_references`)."""
        self._ev.worlds.references.update(paths)

    def suggest(self, n: int | None = None) -> list[DesignJob]:
        """The next batch of evaluations, at most ``n`` (all of the stage's by default; empty: finished, or
        waiting for the optimize stage's candidates or the worlds' references).

        Stages advance when everything they suggested has been ingested; jobs
        already ingested (a resumed run) are never suggested again.
        """
        while True:
            jobs = self._new(self._stage_jobs())
            if jobs:
                return jobs if n is None else jobs[:n]
            if not self._advance():
                return []

    def _new(self, jobs: list[DesignJob]) -> list[DesignJob]:
        seen, out = set(), []
        for j in jobs:
            key = j.key
            if key not in self._store and key not in seen:
                seen.add(key)
                out.append(j)
        return out

    def _set_stage(self, stage: Stage) -> None:
        self._stage = self._store.stage = stage

    def _advance(self) -> bool:
        if self._stage is Stage.DONE or (self._stage is Stage.OPTIMIZE and not self._optimized):
            return False  # the driver runs the optimize stage, then calls ingest_candidates
        if self._stage is Stage.WORLDS and self.needed_references():
            return False  # the driver simulates the worlds' references, then calls ingest_references
        order = list(Stage)
        self._set_stage(order[order.index(self._stage) + 1])
        return True

    def _stage_jobs(self) -> list[DesignJob]:
        make = {Stage.SCREEN: self._screen, Stage.LEARNERS: self._learners, Stage.CURVES: self._curves,
                Stage.REFINE: self._refine, Stage.VERIFY: self._verify, Stage.DECIDE: self._decide,
                Stage.WORLDS: self._worlds}.get(self._stage)
        return [] if make is None else make()

    # --------------------------------------------------------------- stages
    def _screen(self) -> list[DesignJob]:
        designs = list(dict.fromkeys(d for line in self._lines for d in line.designs))
        return [self.job(Evaluator.BOUND, r, d) for r in self._ev.requirements for d in designs]

    def _learners(self) -> list[DesignJob]:
        return [self.job(Evaluator.TRAINED, r, self._ev.base, s, model=m) for r, m, s in self._ev.learner_runs()]

    def _curves(self) -> list[DesignJob]:
        """Every bound-passing point of a line, or on a monotone axis the costliest point not yet trained, until
        one is not met (one per line and round); and the learner's learning curve at the reference design."""
        ev = self._ev
        jobs = [with_budget(self.job(Evaluator.LEARNING_CURVE, r, ev.base, i), n) for r, n, i in curve_runs(ev)]
        for req in ev.requirements:
            for line in self._lines:
                pts = [d for d in line.designs if ev.bound_meets(req, d)]
                if line.axis not in MONOTONE:
                    jobs += [self.job(Evaluator.TRAINED, req, d) for d in pts]
                    continue
                for d in sorted(pts, key=lambda d: d.value(line.axis, ev.space.sensor),
                                reverse=MORE_IS_BETTER[line.axis]):
                    tv = ev.trained_value(req, d)
                    if tv is None:
                        jobs.append(self.job(Evaluator.TRAINED, req, d))
                        break
                    if tv.verdict == NOT_MET:
                        break
        return jobs

    def _refine(self) -> list[DesignJob]:
        """Bisection of each monotone line at the reference layout, between its last met and first missed point."""
        ev, jobs = self._ev, []
        for req in ev.requirements:
            for line in self._lines:
                axis = line.axis
                if axis not in MONOTONE or line.layout != ev.base.layout:
                    continue
                pts = line_points(ev, req, axis, line.base)
                if sum(p.design not in line.designs and p.judged for p in pts) >= ev.config.refine_steps:
                    continue
                ends = bracket(pts, req, MORE_IS_BETTER[axis])
                if ends is None:
                    continue
                a, b = ends
                if axis == "n_bins":  # whole bins: stop when the bracket is one bin wide
                    mid = int(round(0.5 * (a + b)))
                    if mid in (int(a), int(b)):
                        continue
                    d = line.base.replace(n_bins=mid)
                else:
                    mid = math.sqrt(a * b) if axis == "photon_fraction" else 0.5 * (a + b)
                    d = line.base.replace(**{axis: float(round(mid, 6))})
                if ev.bound(req, d) is None:
                    jobs.append(self.job(Evaluator.BOUND, req, d))
                elif ev.bound_meets(req, d):
                    jobs.append(self.job(Evaluator.TRAINED, req, d))
        return jobs

    def _verify(self) -> list[DesignJob]:
        ev = self._ev
        jobs = [self.job(Evaluator.TRAINED, r, c.design, s) for r in ev.requirements
                for c in self._store.candidates.get(r.name, []) for s in range(ev.config.seeds)]
        if ev.has_real:  # the same designs trained on simulated captures: where do sim and real disagree?
            jobs += [self.job(Evaluator.TRAINED_SIM, r, d) for r in ev.requirements for d in ev.trained_designs(r)]
        return jobs

    def _decide(self) -> list[DesignJob]:
        """One more seed: the cheapest undecided candidate per requirement, then each undecided row's design."""
        ev = self._ev
        jobs, left = [], ev.budget_left()
        for req in ev.requirements:
            for c in ev.candidates(req):
                tv = c.trained
                if tv is not None and tv.verdict == MET:
                    break
                if tv is not None and tv.verdict == UNDECIDED:
                    if tv.seeds < ev.config.max_seeds and len(jobs) < left:
                        jobs.append(self.job(Evaluator.TRAINED, req, c.design, len(ev.runs(req, c.design))))
                    break  # one per requirement and round: the cheapest undecided
        keys = {j.key for j in jobs}   # then the undecided per-parameter rows, with what budget is left
        for req in ev.requirements:
            for d in undecided_lines(ev, req):
                job = self.job(Evaluator.TRAINED, req, d, len(ev.runs(req, d)))
                if len(jobs) < left and job.key not in keys:
                    jobs.append(job)
                    keys.add(job.key)
        return jobs + [with_budget(self.job(Evaluator.LEARNING_CURVE, r, ev.base, i), n)
                       for r, n, i in undecided_target_runs(ev)]

    def _worlds(self) -> list[DesignJob]:
        jobs = []
        for run in [] if self._ev.worlds is None else robust.world_runs(self._ev):
            where = robust.world_target(self._ev, run.world, run.design.layout)
            if where is not None:
                jobs.append(self.job(Evaluator.TRAINED, run.requirement, run.design, run.index, reference=where[0],
                                     world=where[1]))
        return jobs
