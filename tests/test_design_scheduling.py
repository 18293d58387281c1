"""A stage's evaluations start longest first (nlosplan.planner.design.scheduling)."""

import math

from nlosplan.planner.design.evaluation import Evaluation
from nlosplan.planner.design.jobs import DesignJob
from nlosplan.planner.design.scheduling import SECONDS_PER_CELL, RunTimes, job_kind
from nlosplan.planner.design.space import Design


def _job(evaluator, task, zones, n_bins=128, train=None, seed=0):
    fid = {} if train is None else {"train_captures": train}
    return DesignJob(evaluator, task, Design(zones=zones, n_bins=n_bins), seed, fid, None, "ref.npz", {})


def _record(job, seconds):
    """The job's result as the search reads it (a record with a value, through :meth:`Evaluation.from_record`)."""
    return Evaluation.from_record({**job.to_dict(), "metric": "m", "value": 0.5, "lo": 0.4, "hi": 0.6,
                                   "status": "ok", "reason": "", "extra": {}, "seconds": seconds})


def test_unmeasured_kinds_are_ordered_by_cells_and_training_captures():
    t = RunTimes()
    small, large, curve = _job("trained", "shape", (3, 3)), _job("trained", "shape", (8, 8)), \
        _job("learning_curve", "loc", (3, 3), train=25200)
    assert math.isclose(t.estimate(large), SECONDS_PER_CELL * 64 * 128)
    assert math.isclose(t.estimate(curve), SECONDS_PER_CELL * 9 * 128 * 12)
    assert t.longest_first([small, large, curve]) == [curve, large, small]


def test_a_measured_kind_takes_its_mean_and_ties_keep_their_order():
    small, large = _job("bound", "loc", (8, 8)), _job("trained", "size", (2, 2))
    t = RunTimes([_record(small, 0.05), _record(small, 0.07), _record(large, 0.9)])
    assert math.isclose(t.estimate(small), 0.06) and math.isclose(t.estimate(large), 0.9)
    assert t.longest_first([small, large]) == [large, small]
    a, b = _job("trained", "size", (2, 2), seed=1), _job("trained", "size", (2, 2), seed=2)
    assert t.longest_first([a, b]) == [a, b] and t.longest_first([b, a]) == [b, a]
    t.add(_record(large, float("nan")))  # skipped
    assert math.isclose(t.estimate(large), 0.9)


def test_a_jobs_kind_and_its_results_kind_are_one():
    job = _job("learning_curve", "shape", (3, 3), n_bins=64, train=4200)
    ev = _record(job, 1.0)
    assert job_kind(job) == job_kind(ev) == ("learning_curve", "shape", "3x3", 64, 4200)
    assert RunTimes([ev]).estimate(job) == 1.0
