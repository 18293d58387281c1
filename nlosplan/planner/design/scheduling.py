"""The order a stage's evaluations start in: the longest first.

A stage ends when its last evaluation does, so an 8x8 evaluation (2-3 s on a 2-core machine) that starts last keeps
one worker busy while the others wait: the cold main job left ~43 core-seconds idle at its stages' ends. The
executors start jobs in the order given (:mod:`.executors`), so :meth:`RunTimes.longest_first` orders each batch by
its expected run time (longest processing time first): the mean seconds this run measured for evaluations of the
same kind (evaluator, task, zone layout, bins and training captures), or, for a kind not seen yet, an estimate from
the histogram's cells. Only the order changes: every evaluation's seed and inputs are its own, and the search takes
its results in any order.
"""

from __future__ import annotations

import math

__all__ = ["RunTimes", "job_kind"]

#: Seconds per histogram cell (zones x bins) of an evaluation of a kind not measured yet, on a 2-core machine (a
#: trained or bound 8x8 x 128 evaluation: ~1.6-1.9 s). Only the order of estimates matters, and a measured kind
#: replaces it.
SECONDS_PER_CELL = 2e-4

#: Training captures the per-cell estimate stands for (the default budget: 2,100).
BASE_TRAIN_CAPTURES = 2100


def _name(v) -> str:
    return str(getattr(v, "value", v))


def job_kind(item) -> tuple:
    """What an evaluation's run time follows, of a job (:class:`~.jobs.DesignJob`) or its result
    (:class:`~.evaluation.Evaluation`): ``(evaluator, task, "RxC", n_bins, train_captures)``."""
    d = item.design
    train = (item.fidelity or {}).get("train_captures")
    return (_name(item.evaluator), _name(item.task), f"{d.zones[0]}x{d.zones[1]}", int(d.n_bins),
            None if train is None else int(train))


class RunTimes:
    """Seconds the run's evaluations took, by kind (:func:`job_kind`), and the order they imply."""

    def __init__(self, evaluations=()):
        self._total: dict[tuple, float] = {}
        self._count: dict[tuple, int] = {}
        for ev in evaluations:
            self.add(ev)

    def add(self, ev) -> None:
        """Learn from one :class:`~.evaluation.Evaluation` (its ``seconds``; one without finite seconds is skipped)."""
        s = ev.seconds
        if s is None or not math.isfinite(s):
            return
        k = job_kind(ev)
        self._total[k] = self._total.get(k, 0.0) + float(s)
        self._count[k] = self._count.get(k, 0) + 1

    def estimate(self, job) -> float:
        """Expected seconds of ``job`` (a :class:`~.jobs.DesignJob`)."""
        k = job_kind(job)
        if k in self._count:
            return self._total[k] / self._count[k]
        rows, cols = job.design.zones
        budget = k[4] / BASE_TRAIN_CAPTURES if k[4] else 1.0
        return SECONDS_PER_CELL * rows * cols * k[3] * budget

    def longest_first(self, jobs: list) -> list:
        """``jobs`` by expected seconds, longest first (ties keep their order)."""
        return sorted(jobs, key=self.estimate, reverse=True)
