"""One evaluation as the design search keeps it: a frozen, typed record of one result line.

An executor hands back each result as a plain dict, and that dict is what
``design_evaluations.jsonl`` holds, one per line
(:func:`~nlosplan.planner.design.evaluators.evaluate`; a resumed run reads the
same lines back). The search types a result once, when it ingests it
(:meth:`Evaluation.from_record`): a misspelt field is an error there, not a
``None`` three modules later. Everyone after reads the typed record from the
evidence store (:mod:`~nlosplan.planner.design.evidence`).

Adding an evaluator is one member of :class:`Evaluator` (with the table of
knobs it reads), its branch in
:func:`~nlosplan.planner.design.evaluators.evaluate`, and the stage that
suggests it (:mod:`~nlosplan.planner.design.search`).
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from enum import StrEnum
from pathlib import Path

from nlosplan.planner.design.requirements import Condition, Task
from nlosplan.planner.design.space import Design

__all__ = ["Evaluator", "Status", "Evaluation", "Place", "place_of"]


class Evaluator(StrEnum):
    """Who judged a design; a member is its logged name (``Evaluator.BOUND == "bound"``)."""

    #: The fast bound: Cramér–Rao for localization, the ideal observer for the classes.
    BOUND = "bound"
    #: The task's learner on the trained reference (real captures when the run has them).
    TRAINED = "trained"
    #: The same learner on the simulated reference, beside real captures (where do sim and real disagree?).
    TRAINED_SIM = "trained_sim"
    #: The task's learner at the reference design with another training budget (its knob ``train_captures``):
    #: the learning curve up to DENALI's 25,200 captures (:mod:`~nlosplan.planner.design.learning_curve`).
    LEARNING_CURVE = "learning_curve"

    @property
    def knobs(self) -> str:
        """The fidelity table it reads (``[search.fidelity.NAME]``): ``trained_sim`` and ``learning_curve`` train as
        ``trained`` does."""
        return "bound" if self is Evaluator.BOUND else "trained"

    @property
    def trains(self) -> bool:
        """Whether it trains a learner (its runs carry the model in their knobs)."""
        return self is not Evaluator.BOUND


class Status(StrEnum):
    """How an evaluation ended: ``ok``, ``unreachable`` (the design is finer than its reference) or ``failed``."""

    OK = "ok"
    UNREACHABLE = "unreachable"
    FAILED = "failed"


#: Where an evaluation ran outside the nominal model: ``(reference file name, the world's overrides as JSON)``.
Place = tuple[str, str]


def place_of(reference: str | None, world: dict | None) -> Place | None:
    """The place of a run in a world (None: the nominal model). The reference by file name, as in the job's key."""
    if world is None:
        return None
    return Path(str(reference)).name, json.dumps(world, sort_keys=True, default=str)


@dataclass(frozen=True)
class Evaluation:
    """One evaluation of one design on one task, as ingested.

    Attributes
    ----------
    key : str
        The job's key (:attr:`~nlosplan.planner.design.jobs.DesignJob.key`).
    evaluator : Evaluator
    task : Task
    design : Design
    seed : int
        The evaluation seed (:meth:`~nlosplan.planner.design.search_config.SearchConfig.seed_of` a run index).
    fidelity : dict
        The evaluator's knobs (``model`` for a learner).
    condition : Condition or None
        The rows the metric was computed on.
    reference : str
        Path of the reference the design was emulated from.
    world : dict or None
        A world's sensor overrides; None in the nominal model.
    metric : str
        ``loc_rmse`` (m) or ``top1_acc``.
    value, lo, hi : float
        The metric and its 95 % interval (NaN when the run did not finish).
    seconds : float
        Run time, s (0 when the worker died before it could say).
    status : Status
    reason : str
        Why it is unreachable or failed, or a note (e.g. scenes not identifiable).
    extra : dict
        Details of the evaluator (epochs, train size, draws, ...).
    """

    key: str
    evaluator: Evaluator
    task: Task
    design: Design
    seed: int
    fidelity: dict = field(default_factory=dict)
    condition: Condition | None = None
    reference: str = ""
    world: dict | None = None
    metric: str = ""
    value: float = math.nan
    lo: float = math.nan
    hi: float = math.nan
    seconds: float = 0.0
    status: Status = Status.OK
    reason: str = ""
    extra: dict = field(default_factory=dict)

    @classmethod
    def from_record(cls, record: dict) -> "Evaluation":
        """Type one result line (:func:`~nlosplan.planner.design.evaluators.evaluate`'s dict, or an executor's
        ``failed`` record, which carries only the job's fields, ``status`` and ``reason``).

        Raises
        ------
        KeyError, ValueError, TypeError
            A field the record must have is missing or not of its type.
        """
        r = dict(record)
        cond = r.get("condition")
        return cls(key=str(r["key"]), evaluator=Evaluator(r["evaluator"]), task=Task(r["task"]),
                   design=Design.from_dict(r["design"]), seed=int(r["seed"]), fidelity=dict(r.get("fidelity") or {}),
                   condition=Condition.parse(cond) if isinstance(cond, str) else cond,
                   reference=str(r.get("reference", "")), world=r.get("world"), metric=str(r.get("metric", "")),
                   value=float(r.get("value", math.nan)), lo=float(r.get("lo", math.nan)),
                   hi=float(r.get("hi", math.nan)), seconds=float(r.get("seconds", 0.0)),
                   status=Status(r.get("status", "ok")), reason=str(r.get("reason", "")),
                   extra=dict(r.get("extra") or {}))

    @property
    def model(self) -> str:
        """The learner it trained (empty for a bound)."""
        return str(self.fidelity.get("model", "")) if self.evaluator.trains else ""

    @property
    def n_train(self) -> int | None:
        """The training captures a learner had (``extra["n_train"]``; None for a bound or an old log line)."""
        n = self.extra.get("n_train")
        return None if n is None else int(n)

    @property
    def place(self) -> Place | None:
        """Where it ran: None in the nominal model, else :func:`place_of` its reference and world."""
        return place_of(self.reference, self.world)

    @property
    def ok(self) -> bool:
        return self.status is Status.OK

    @property
    def finite(self) -> bool:
        """Finished with a finite metric."""
        return self.ok and math.isfinite(self.value)
