"""The optimize stage's branch and bound (:func:`run_optimize`): cheapest floor first, in waves, and a choice whose
cheapest setting costs more than the candidates already found is not run; the candidates are those of a full run."""

import math

import pytest

from nlosplan.planner.design.optimize import choice_floor, collect_candidates, optimize_jobs, run_optimize
from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.search import DesignSearch, SearchConfig
from nlosplan.planner.design.space import DesignSpace

SPACE = DesignSpace(zones=((1, 1), (2, 2), (3, 3), (8, 8)), bin_factors=(1, 2, 4),
                    axes=("zones", "jitter_fwhm_ps", "photon_fraction"))
REFS = {"1x1": "ref1.npz", "2x2": "ref2.npz", "3x3": "ref3.npz", "8x8": "ref8.npz"}
LOC, SHAPE = Requirement("loc", 0.05), Requirement("shape", 0.35)


def _jobs():
    search = DesignSearch(SPACE, [LOC, SHAPE], SearchConfig(grid_points=3, seeds=1), REFS)
    return optimize_jobs(search.evidence, lambda req, d: search.job("bound", req, d)), search.evidence


def fake_choice(job) -> dict:
    """A choice's cheapest feasible design costs its floor plus a margin; 1x1 misses the shape task."""
    if job.requirement.task == "shape" and job.base.layout == "1x1":
        return {"requirement": job.requirement.name, "design": None, "cost": math.nan, "status": "infeasible",
                "choice": job.base.layout, "evaluations": 1, "seconds": 0.0}
    d = job.base
    return {"requirement": job.requirement.name, "design": d.to_dict(), "cost": choice_floor(job) + 0.25,
            "predicted": 0.0, "bound": 0.0, "status": "feasible", "reason": "", "choice": d.layout,
            "evaluations": 5, "seconds": 0.0}


def test_floor_is_the_cheapest_setting_and_bounds_every_design_of_the_choice():
    jobs, ev = _jobs()
    for job in jobs:
        floor = choice_floor(job)
        assert floor <= ev.cost(job.base) and floor >= 0
        assert floor == pytest.approx(ev.cost_model(job.base.replace(
            jitter_fwhm_ps=SPACE.jitter_fwhm_ps[1], photon_fraction=SPACE.photon_fraction[0], n_bins=SPACE.n_bins[0]),
            SPACE))
    floors = {(j.base.layout, j.base.bin_factor): choice_floor(j) for j in jobs if j.requirement == LOC}
    assert floors[("8x8", 1)] > floors[("3x3", 1)] > floors[("1x1", 1)] and floors[("1x1", 1)] > floors[("1x1", 4)]


def lazy_executor(width: int, ran: list, in_flight: list):
    """Like an executor's ``map(..., ahead=width)``: takes a job only while fewer than ``width`` are in flight,
    finishes the oldest first."""

    def run(jobs):
        source, flight = iter(jobs), []
        while True:
            while len(flight) < width and (job := next(source, None)) is not None:
                flight.append(job)
            in_flight.append(len(flight))
            if not flight:
                return
            job = flight.pop(0)
            ran.append(job)
            yield job, fake_choice(job)

    return run


@pytest.mark.parametrize("per_task,width", [(1, 1), (2, 2), (2, 3)])
def test_pruned_choices_could_not_change_the_candidates(per_task, width):
    jobs, ev = _jobs()
    ran, in_flight = [], []
    rows = run_optimize(jobs, per_task, lazy_executor(width, ran, in_flight))
    full = [fake_choice(j) for j in jobs]
    assert collect_candidates(ev, rows, per_task) == collect_candidates(ev, full, per_task)
    assert max(in_flight) == width and len(ran) == len({id(j) for j in ran})
    assert [choice_floor(j) for j in ran] == sorted(choice_floor(j) for j in ran)  # cheapest floor first
    pruned = [r for r in rows if r["status"] == "pruned"]
    assert len(pruned) + len(ran) == len(jobs) and len(pruned) >= len(jobs) // 3  # the 8x8 choices at least
    for r in pruned:
        floor, bar = r["floor"], r["bar"]
        assert r["reason"] == (f"its cheapest setting costs {floor:.2f}, above the {per_task} cheapest feasible "
                               f"designs found ({bar:.2f})") and r["design"] is None and math.isnan(r["cost"])
        found = sorted(x["cost"] for x in rows if x["requirement"] == r["requirement"] and x["status"] == "feasible")
        assert floor > bar >= found[per_task - 1]
    # the shape task's 1x1 choices are infeasible: they never count toward the bar
    assert any(r["status"] == "infeasible" for r in rows)


def test_more_jobs_in_flight_prune_no_more_than_fewer():
    jobs, _ = _jobs()
    counts = []
    for width in (1, 4, len(jobs)):
        ran: list = []
        run_optimize(jobs, 2, lazy_executor(width, ran, []))
        counts.append(len(ran))
    assert counts[0] <= counts[1] <= counts[2] == len(jobs)  # all offered at once: nothing can be pruned


def test_bad_settings_are_refused():
    jobs, _ = _jobs()
    with pytest.raises(ValueError, match="per_task=0"):
        run_optimize(jobs, 0, lambda js: iter(()))
