"""The design search's evidence: every evaluation, typed and indexed, and the questions its neighbours ask of it.

:class:`EvidenceStore` holds the :class:`~nlosplan.planner.design.evaluation.Evaluation` records the search
ingested (in order), the candidates of its optimize stage and how far it got; only the search writes to it.
:class:`Evidence` is its read-only face, with what a query needs to know about the run (space,
requirements, knobs, cost, worlds): the runs of a design, its bound, the task's learner and run-to-run spread,
a design's :class:`~nlosplan.planner.design.verdicts.Estimate` over its seeds, the bound-to-trained gap, the
candidates and the budget. The stage machine (:mod:`~nlosplan.planner.design.search`), the worlds
(:mod:`~nlosplan.planner.design.robust`), the optimizer, the summary and the progress page read this, never the
search. A lookup goes by what it asks (evaluator, task, condition, design, learner, place, seed): no job is
rebuilt or hashed to find a result.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from nlosplan.planner.design.budget import TRAIN_CAPTURES
from nlosplan.planner.design.cost import CostModel
from nlosplan.planner.design.evaluation import Evaluation, Evaluator, Place
from nlosplan.planner.design.requirements import Condition, Requirement, Task
from nlosplan.planner.design.search_config import SearchConfig
from nlosplan.planner.design.space import Design, DesignSpace
from nlosplan.planner.design.verdicts import (MET, UNDECIDED, Estimate, Spread, metric_to_score, pooled_spread,
                                              score_to_metric, seed_interval)

__all__ = ["EvidenceStore", "Evidence", "Candidate", "Gap"]

#: A run's address in the store, its seed aside: (evaluator, task, condition, design, learner, place, budget);
#: the budget is a learning-curve run's training captures (None for every other evaluator: their budget is the run's).
Cell = tuple[Evaluator, Task, Condition | None, Design, str, Place | None, int | None]


def _cell(ev: Evaluation) -> Cell:
    budget = int(ev.fidelity[TRAIN_CAPTURES]) if ev.evaluator is Evaluator.LEARNING_CURVE else None
    return ev.evaluator, ev.task, ev.condition, ev.design, ev.model, ev.place, budget


@dataclass(frozen=True)
class Candidate:
    """A design the verify stage runs for a requirement (from the optimizer or the scans).

    Attributes
    ----------
    design : Design
    cost : float
    source : str
        ``optimized``, ``scans``, or why it was examined.
    trained : Estimate or None
        Its learner's metric over the seeds run (filled by :meth:`Evidence.candidates`).
    row : dict
        The record it was read from (the optimizer's result row; empty for a scanned design): the checkpoint
        keeps it as it was.
    """

    design: Design
    cost: float
    source: str = "scans"
    trained: Estimate | None = None
    row: dict = field(default_factory=dict)

    def to_dict(self) -> dict:
        """As ``design_checkpoint.json`` keeps it: the optimizer's row with the design, cost and source."""
        return {**self.row, "design": self.design.to_dict(), "cost": self.cost, "source": self.source}

    @classmethod
    def from_dict(cls, data: dict) -> "Candidate":
        row = {k: v for k, v in data.items() if k != "source"}
        return cls(Design.from_dict(data["design"]), float(data["cost"]), str(data.get("source", "scans")), None, row)


@dataclass(frozen=True)
class Gap:
    """The bound-to-trained gap of a task on the score scale: the median over ``n`` designs, ``spread`` its IQR."""

    value: float = 0.0
    n: int = 0
    spread: float = math.nan

    def to_dict(self) -> dict:
        return {"value": self.value, "n": self.n, "spread": self.spread}


class EvidenceStore:
    """Every evaluation ingested, in order, indexed by cell and seed; the optimize stage's candidates; the stage.

    Only the search writes here (:meth:`add`, :meth:`set_candidates`, ``stage``); readers get an :class:`Evidence`.
    An evaluation ingested again under the same key replaces the first (as a resumed log may hold it twice).
    """

    def __init__(self) -> None:
        self._by_key: dict[str, Evaluation] = {}
        self._cells: dict[Cell, dict[int, Evaluation]] = {}
        self._designs: dict[tuple[Task, Condition | None], dict[Design, None]] = {}
        self.version = 0
        self.stage = "screen"
        self.candidates: dict[str, list[Candidate]] = {}
        self.optimize_log: list[dict] = []

    def add(self, ev: Evaluation) -> None:
        self._by_key[ev.key] = ev
        self._cells.setdefault(_cell(ev), {})[ev.seed] = ev
        self._designs.setdefault((ev.task, ev.condition), {}).setdefault(ev.design)
        self.version += 1

    def set_candidates(self, candidates: dict[str, list[Candidate]], log: list[dict]) -> None:
        self.candidates, self.optimize_log = candidates, log

    def __contains__(self, key: str) -> bool:
        return key in self._by_key

    def __len__(self) -> int:
        return len(self._by_key)

    def __iter__(self) -> Iterator[Evaluation]:
        return iter(self._by_key.values())

    def get(self, cell: Cell, seed: int) -> Evaluation | None:
        return self._cells.get(cell, {}).get(seed)

    def designs(self, task: Task, condition: Condition | None) -> list[Design]:
        """Every design evaluated for ``task`` under ``condition`` (any evaluator or world), first seen first."""
        return list(self._designs.get((task, condition), ()))


class Evidence:
    """The read-only face of an :class:`EvidenceStore`, with what a question needs to know about the run.

    Parameters
    ----------
    store : EvidenceStore
    space : DesignSpace
    requirements : sequence of Requirement
    config : SearchConfig
    cost : CostModel
    worlds : WorldPlan, optional
        The plausible worlds (:class:`~nlosplan.planner.design.robust.WorldPlan`); None: no worlds stage.
    trained_references : dict
        Zone layout -> the trained evaluator's reference (real captures when ``has_real``).
    has_real : bool
        The trained evaluator reads real captures (and ``trained_sim`` the simulated ones).
    """

    def __init__(self, store: EvidenceStore, space: DesignSpace, requirements, config: SearchConfig, cost: CostModel,
                 worlds=None, trained_references: dict | None = None, has_real: bool = False):
        self._store = store
        self.space, self.requirements, self.config, self.cost_model = space, tuple(requirements), config, cost
        self.worlds, self.trained_references, self.has_real = worlds, dict(trained_references or {}), has_real
        self.base = space.reference_design()
        self._learners: dict[Task, str] = {}
        self._spreads: dict = {}

    # ------------------------------------------------------------- records
    def __len__(self) -> int:
        return len(self._store)

    def records(self) -> Iterator[Evaluation]:
        """Every evaluation, in the order ingested."""
        return iter(self._store)

    @property
    def stage(self) -> str:
        """The search's stage when last asked (:class:`~nlosplan.planner.design.search.Stage`)."""
        return self._store.stage

    @property
    def optimize_log(self) -> list[dict]:
        """The optimize stage's result rows (:func:`~nlosplan.planner.design.optimize.optimize_choice`)."""
        return self._store.optimize_log

    def cost(self, d: Design) -> float:
        return self.cost_model(d, self.space)

    def designs(self, req: Requirement) -> list[Design]:
        """Every design evaluated for ``req``'s task under its condition, first seen first."""
        return self._store.designs(req.task, req.condition)

    def run(self, evaluator: Evaluator, req: Requirement, d: Design, i: int = 0, *, model: str | None = None,
            place: Place | None = None, budget: int | None = None) -> Evaluation | None:
        """``d``'s ``i``-th run by ``evaluator`` for ``req`` (a learner: ``model``, default the task's learner; a
        learning-curve run: ``budget``, its training captures)."""
        model = (model or self.learner(req.task)) if evaluator.trains else ""
        budget = int(budget) if evaluator is Evaluator.LEARNING_CURVE else None
        return self._store.get((evaluator, req.task, req.condition, d, model, place, budget), self.config.seed_of(i))

    def runs(self, req: Requirement, d: Design, evaluator: Evaluator = Evaluator.TRAINED) -> list[Evaluation]:
        """The learner's finished runs of ``d`` (nominal model), in seed order."""
        found = (self.run(evaluator, req, d, i) for i in range(self.config.max_seeds))
        return [r for r in found if r is not None]

    def bound(self, req: Requirement, d: Design) -> Evaluation | None:
        return self.run(Evaluator.BOUND, req, d)

    def bound_meets(self, req: Requirement, d: Design) -> bool:
        """Does the design's bound meet the requirement (optimistic side of its interval)? A failed bound does not
        screen out; one not evaluated does not meet."""
        r = self.bound(req, d)
        if r is None or not r.ok:
            return r is not None and r.status == "failed"
        best = r.lo if req.smaller_is_better else r.hi
        return math.isfinite(best) and req.met(best)

    # ------------------------------------------------------------ learners
    def task_requirements(self) -> list[Requirement]:
        """The first requirement of each task (its condition is the one learners are compared on)."""
        return list({r.task: r for r in reversed(self.requirements)}.values())[::-1]

    def contenders(self, req: Requirement) -> tuple[str, ...] | None:
        """The candidate models still in the running for ``req``'s task on the reference design (None until every
        candidate has its first seed there).

        A candidate stays when the optimistic end of its first run's interval reaches the best first figure; the
        others are not trained at more seeds (a network several centimetres behind the leader after one seed does
        not become the learner by its third). Failed or non-finite first runs drop out, unless every one did.
        """
        models = self.config.models
        if len(models) == 1:
            return models
        first = {m: self.run(Evaluator.TRAINED, req, self.base, 0, model=m) for m in models}
        if any(r is None for r in first.values()):
            return None
        good = {m: r for m, r in first.items() if r.ok and r.finite}
        if not good:
            return models
        if req.smaller_is_better:
            lead = min(r.value for r in good.values())
            return tuple(m for m, r in good.items() if not r.lo > lead)   # a NaN end keeps it in
        lead = max(r.value for r in good.values())
        return tuple(m for m, r in good.items() if not r.hi < lead)

    def learner_runs(self) -> list[tuple[Requirement, str, int]]:
        """The learner comparison's runs on the reference design, ``(requirement, model, seed)``: every candidate's
        first seed, then ``seeds`` seeds of each candidate still in contention (:meth:`contenders`)."""
        out = []
        for req in self.task_requirements():
            models = self.contenders(req)
            seeds = range(1) if models is None else range(self.config.seeds)
            out += [(req, m, s) for m in (self.config.models if models is None else models) for s in seeds]
        return out

    def learner(self, task: Task) -> str:
        """The task's learner: the candidate model in contention with the best mean metric on the reference design.

        Until every contender has run its seeds there, the first of ``models``.
        """
        if task in self._learners:
            return self._learners[task]
        models = self.config.models
        req = next((r for r in self.task_requirements() if r.task == task), None)
        if len(models) == 1 or req is None:
            return models[0]
        contenders = self.contenders(req)
        if contenders is None:
            return models[0]
        means = {}
        for m in contenders:
            recs = [self.run(Evaluator.TRAINED, req, self.base, s, model=m) for s in range(self.config.seeds)]
            if any(r is None for r in recs):
                return models[0]
            vals = [r.value for r in recs if r.finite]
            if vals:
                means[m] = float(np.mean(vals))
        best = models[0] if not means else min(means, key=lambda m: (means[m] if req.smaller_is_better
                                                                      else -means[m], models.index(m)))
        self._learners[task] = best
        return best

    def spread(self, req: Requirement) -> Spread:
        """The run-to-run variance of the requirement's metric (the learner's, nominal model), pooled over designs."""
        key = (req.task, req.condition, self._store.version)
        if key not in self._spreads:
            groups: dict[Design, list[float]] = {}
            model = self.learner(req.task)
            for r in self._store:
                if (r.evaluator is Evaluator.TRAINED and r.task == req.task and r.world is None
                        and r.condition == req.condition and r.model == model and r.ok):
                    groups.setdefault(r.design, []).append(r.value)
            self._spreads = {k: v for k, v in self._spreads.items() if k[2] == self._store.version}
            self._spreads[key] = pooled_spread(req, groups.values())
        return self._spreads[key]

    def trained_value(self, req: Requirement, d: Design) -> Estimate | None:
        """The learner's mean metric over the seeds run, with its 95 % interval and verdict (None if never trained).

        See :func:`~nlosplan.planner.design.verdicts.seed_interval`.
        """
        return seed_interval(req, self.runs(req, d), self.spread(req))

    def trained_designs(self, req: Requirement) -> list[Design]:
        """Designs with a successful trained evaluation of ``req``'s task (nominal model, any condition), sorted."""
        return sorted({r.design for r in self._store
                       if r.task == req.task and r.evaluator is Evaluator.TRAINED and r.ok and r.world is None})

    # ------------------------------------------------------ multi-fidelity
    def gap(self, req: Requirement) -> Gap:
        """The bound-to-trained gap of a task over every design evaluated by both.

        Localization: the median log ratio trained / bound; accuracies: the median logit difference.
        """
        diffs = []
        for d in {r.design for r in self._store if r.task == req.task}:
            b, t = self.bound(req, d), self.trained_value(req, d)
            if b is None or t is None or not b.ok or not math.isfinite(b.value):
                continue
            diffs.append(metric_to_score(req, t.value) - metric_to_score(req, b.value))
        if not diffs:
            return Gap()
        q1, med, q3 = np.percentile(diffs, [25, 50, 75])
        return Gap(float(med), len(diffs), float(q3 - q1))

    def predict(self, req: Requirement, bound_value: float) -> float:
        """The trained metric predicted from a bound value and the measured gap."""
        return score_to_metric(req, metric_to_score(req, bound_value) + self.gap(req).value)

    # ------------------------------------------------------- budget, decide
    def extra_spent(self, worlds: bool = False) -> int:
        """Extra evaluations spent deciding: seeds beyond ``seeds`` in the nominal model (``[search] budget``), or
        with ``worlds`` beyond each world's first seed, controls included (``[worlds] budget``)."""
        n, base = 0, self.config.seed_of(0)
        for r in self._store:
            if r.evaluator is Evaluator.TRAINED and (r.world is not None) == worlds:
                n += r.seed - base >= (1 if worlds else self.config.seeds)
        return n

    def budget_left(self) -> int:
        """Extra nominal evaluations left to the decide stage (``[search] budget``)."""
        return max(0, self.config.budget - self.extra_spent())

    def worlds_budget_left(self) -> int:
        """Extra world evaluations left to the worlds stage (``[worlds] budget``; 0 without worlds)."""
        return 0 if self.worlds is None else max(0, self.worlds.config.budget - self.extra_spent(worlds=True))

    def candidates(self, req: Requirement) -> list[Candidate]:
        """The requirement's candidates from the optimize stage, cheapest first, each with its ``trained`` estimate."""
        out = [Candidate(c.design, self.cost(c.design), c.source, self.trained_value(req, c.design), c.row)
               for c in self._store.candidates.get(req.name, [])]
        return sorted(out, key=lambda c: (c.cost, c.design))

    def scan_candidates(self, req: Requirement, n: int) -> list[Candidate]:
        """The ``n`` cheapest scanned designs whose mean meets ``req``, and the cheapest met one if not among them.

        When no mean meets it, the undecided design closest to meeting it (so that seeds can decide it).
        """
        rows, undecided = [], []
        for d in self.trained_designs(req):
            tv = self.trained_value(req, d)
            if tv is None:
                continue
            if req.met(tv.value):
                rows.append((self.cost(d), d, tv.verdict))
            elif tv.verdict == UNDECIDED:
                undecided.append((-req.margin(tv.value), self.cost(d), d))
        rows.sort(key=lambda r: (r[0], r[1]))
        picked = [(c, d) for c, d, _ in rows[:n]] + [(c, d) for c, d, v in rows[n:] if v == MET][:1]
        if not rows and undecided:
            _, c, d = min(undecided, key=lambda u: (u[0], u[1], u[2]))
            picked = [(c, d)]
        return [Candidate(d, c, "scans") for c, d in picked]

    def decision(self, req: Requirement, tv: Estimate | None) -> str:
        """Why a verified candidate's verdict stands: decided, or undecided and which limit stopped it."""
        if tv is None:
            return "not evaluated"
        if tv.verdict != UNDECIDED:
            return f"{tv.verdict} after {tv.seeds} seed(s)"
        if tv.seeds >= self.config.max_seeds:
            return f"undecided after {tv.seeds} seeds: max_seeds ({self.config.max_seeds}) reached"
        if self.budget_left() <= 0:
            return (f"undecided after {tv.seeds} seed(s): the budget of {self.config.budget} extra evaluations "
                    "is spent")
        if self.stage in ("decide", "worlds", "done"):
            return f"undecided after {tv.seeds} seed(s): a cheaper candidate was decided met first"
        return f"undecided after {tv.seeds} seed(s): the run stopped before the decide stage"
