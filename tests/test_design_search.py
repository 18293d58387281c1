"""The design search as ask/tell, on an analytic stand-in for the evaluators (no simulation, no training)."""

import math

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.planner.design.cost import CostModel
from nlosplan.planner.design.jobs import DesignJob
from nlosplan.planner.design.lines import line_points
from nlosplan.planner.design.requirements import Requirement, parse_requirement
from nlosplan.planner.design.search import DesignSearch, SearchConfig, Stage
from nlosplan.planner.design.space import Design, DesignSpace
from nlosplan.planner.design.summary import pareto_front, summarize

SPACE = DesignSpace(zones=((1, 1), (3, 3)), bin_factors=(1, 2), axes=("zones", "jitter_fwhm_ps", "photon_fraction"))
REFS = {"1x1": "ref1.npz", "3x3": "ref3.npz"}
LOC = Requirement("loc", 0.05)
SIZE = Requirement("size", 0.9)


def truth(task: str, d: Design, evaluator: str) -> float:
    """Analytic metric: worse with jitter and fewer photons and zones; the bound is optimistic."""
    blur = d.jitter_fwhm_ps / 1000.0
    rmse = 0.02 * (1 + 2.0 * blur) / math.sqrt(d.photon_fraction) * (1.5 if d.zones == (1, 1) else 1.0)
    acc = 1.0 - 0.2 * blur - 0.02 / d.photon_fraction
    if evaluator == "bound":
        return rmse / 2 if task == "loc" else min(1.0, acc + 0.05)
    return rmse if task == "loc" else acc


def fake_result(job: DesignJob) -> dict:
    d = job.design
    v = truth(job.task, d, job.evaluator)
    half = 0.0 if job.evaluator == "bound" and job.task == "loc" else 0.01 * (1 if job.task != "loc" else v)
    return {**job.to_dict(), "metric": "x", "value": v, "lo": v - half, "hi": v + half, "seconds": 0.01,
            "status": "ok", "reason": "", "extra": {}}


def run(search: DesignSearch, calls: list) -> None:
    while True:
        jobs = search.suggest()
        if not jobs and search.stage is Stage.OPTIMIZE:
            search.ingest_candidates({}, [])
            continue
        if not jobs:
            return
        for j in jobs:
            calls.append(j.key)
            search.ingest([fake_result(j)])


def test_search_finds_the_analytic_thresholds_and_resumes_without_recomputing():
    cfg = SearchConfig(grid_points=5, refine_steps=3, seeds=1)
    search = DesignSearch(SPACE, [LOC, SIZE], cfg, REFS)
    calls: list = []
    run(search, calls)
    assert len(calls) == len(set(calls))  # nothing asked twice
    res = summarize(search.evidence)
    rows = {(r["task"], r["parameter"]): r for r in res["requirements"]}
    # localization at 3x3, full photons: rmse = 0.02 (1 + 2 j) <= 0.05  ->  jitter <= 750 ps
    j = rows[("loc", "jitter_fwhm_ps")]
    assert j["feasible"] and j["maximum"] == pytest.approx(750, abs=40)
    assert j["interval"][0] <= 750 + 40 and j["interval"][1] >= 750 - 40
    # photons: 0.02 / sqrt(p) <= 0.05  ->  p >= 0.16
    p = rows[("loc", "photon_fraction")]
    assert p["minimum"] == pytest.approx(0.16, rel=0.25)
    # size: 1 - 0.02 / p >= 0.9 -> p >= 0.2 (jitter 0)
    assert rows[("size", "photon_fraction")]["minimum"] == pytest.approx(0.2, rel=0.25)
    assert rows[("size", "zones")]["minimum"] == "1x1" and "whole range" in rows[("size", "zones")]["note"]
    # a verdict per row, and feasible says the same as the notes
    for r in res["requirements"]:
        assert r["verdict"] in ("met", "not met", "undecided") and r["feasible"] == (r["verdict"] == "met")
        assert ("pessimistic end" in r["note"]) == (r["verdict"] == "undecided")
    # the loc bound (2x optimistic) screens the fewest photons out: never trained there
    ev = search.evidence
    screened = [pt for pt in line_points(ev, LOC, "photon_fraction", ev.base) if pt.screened]
    assert screened and all(pt.trained is None for pt in screened)
    assert res["gap"][LOC.name]["value"] == pytest.approx(math.log(2), abs=1e-9)
    cheapest = {c["task"]: c for c in res["cheapest"]}
    assert cheapest["loc"]["value"] <= 0.05 and cheapest["loc"]["source"].startswith("scans (not verified")
    assert cheapest["loc"]["verdict"] == "met" and cheapest["loc"]["design"]["zones"] in ("1x1", "3x3")

    resumed = DesignSearch(SPACE, [LOC, SIZE], cfg, REFS)
    for r in ev.records():
        resumed.ingest([r])
    again: list = []
    run(resumed, again)
    assert again == []  # a resumed search asks for nothing already told
    assert summarize(resumed.evidence)["requirements"] == res["requirements"]


def test_failed_evaluations_are_recorded_not_fatal():
    search = DesignSearch(SPACE, [SIZE], SearchConfig(grid_points=3, refine_steps=0, seeds=1), REFS)
    n = 0
    while (jobs := search.suggest()) or search.stage is Stage.OPTIMIZE:
        if not jobs:
            search.ingest_candidates({}, [])
            continue
        for j in jobs:
            n += 1
            r = fake_result(j) if n % 3 else {**j.to_dict(), "status": "failed", "reason": "RuntimeError: boom", "value": math.nan,
                                               "lo": math.nan, "hi": math.nan, "seconds": 0.0, "metric": "x"}
            search.ingest([r])
    res = summarize(search.evidence)
    assert res["failures"] and all(f["reason"] == "RuntimeError: boom" for f in res["failures"])
    assert any(r["feasible"] for r in res["requirements"])


def test_pareto_front_is_non_dominated_and_sorted():
    pts = [{"cost": c, "value": v} for c, v in [(1, 0.5), (2, 0.4), (2.5, 0.45), (3, 0.2), (0.5, 0.9), (4, 0.2)]]
    front = pareto_front(pts, smaller_is_better=True)
    assert [(p["cost"], p["value"]) for p in front] == [(0.5, 0.9), (1, 0.5), (2, 0.4), (3, 0.2)]
    acc = pareto_front([{"cost": c, "value": v} for c, v in [(1, 0.5), (2, 0.4), (3, 0.7)]], smaller_is_better=False)
    assert [p["cost"] for p in acc] == [1, 3]


def test_cost_is_zero_at_the_cheapest_design_and_grows_with_hardware():
    cost = CostModel()
    cheapest = Design((1, 1), 2, SPACE.n_bins[0], 1000.0, 1000.0, SPACE.photon_fraction[0])
    assert cost(cheapest, SPACE) == pytest.approx(0.0, abs=1e-12)
    ref = SPACE.reference_design()
    more = [ref.replace(zones=(3, 3)), ref.replace(photon_fraction=1.0), ref.replace(jitter_fwhm_ps=0.0)]
    base = ref.replace(zones=(1, 1), photon_fraction=0.1, jitter_fwhm_ps=500.0)
    for m in [base.replace(zones=(3, 3)), base.replace(photon_fraction=1.0), base.replace(jitter_fwhm_ps=100.0)]:
        assert cost(m, SPACE) > cost(base, SPACE)
    assert more and cost.terms(ref, SPACE)["zones"] == pytest.approx(0.3 * math.log2(9))


def test_design_sensor_keeps_the_photon_budget():
    base = SPACE.sensor
    s = Design((2, 2), 2, 40, 100.0, 50.0, 0.25).sensor(base)
    assert (s.zones_rows, s.zones_cols, s.n_bins) == (2, 2, 40)
    assert s.bin_width_ps == pytest.approx(2 * base.bin_width_ps)
    assert s.photon_scale * s.iterations == pytest.approx(0.25 * base.photon_scale * base.iterations, rel=1e-9)
    hi = Design(photon_fraction=4.0).sensor(base)
    assert hi.iterations == base.iterations and hi.photon_scale == pytest.approx(4 * base.photon_scale)


@pytest.mark.parametrize("text, message", [
    ("loc<=abc", "must look like"), ("shape>=1.5", "in (0, 1]"), ("size>=0.9@size=9in", "unknown condition"),
    ("speed<=3", "must look like")])
def test_bad_requirements_and_spaces_name_the_problem(text, message):
    with pytest.raises(UserError, match=message.replace("(", r"\(").replace(")", r"\)")):
        parse_requirement(text)


def test_bad_spaces_name_the_problem():
    with pytest.raises(UserError, match="n_bins up to 256 exceeds the reference's 128 bins"):
        DesignSpace(n_bins=(32, 256))
    with pytest.raises(UserError, match="unknown design axis speed"):
        DesignSpace(axes=("speed",))
    with pytest.raises(UserError, match="zones 0x3"):
        DesignSpace(zones=("0x3",))
    with pytest.raises(UserError, match="photon_fraction's lower bound must be > 0"):
        DesignSpace(photon_fraction=(0.0, 1.0))
    assert parse_requirement("size>=0.9@lights=on").condition == ("lights", "on")
    assert np.isclose(parse_requirement(" loc <= 0.03 ").threshold, 0.03)


def test_observer_bounds_carry_the_thresholds_they_may_stop_at():
    from nlosplan.planner.design.evaluators import DEFAULT_FIDELITY
    from nlosplan.planner.design.optimize import optimize_jobs

    size_low = Requirement("size", 0.8)
    search = DesignSearch(SPACE, [LOC, SIZE, size_low], SearchConfig(grid_points=3, seeds=1), REFS)
    d = search.evidence.base
    # the ideal observer of a task stops once clear of every threshold of that task; the Cramér–Rao bound is exact
    assert search.job("bound", SIZE, d).fidelity["stop_at"] == [0.8, 0.9]
    assert search.job("bound", SIZE, d).key == search.job("bound", size_low, d).key  # one job for both
    assert "stop_at" not in search.job("bound", LOC, d).fidelity
    assert "stop_at" not in search.job("trained", SIZE, d).fidelity
    assert DEFAULT_FIDELITY["bound"]["looks"] > 1
    # one look: every draw, no thresholds in the job
    fid = {k: dict(v) for k, v in DEFAULT_FIDELITY.items()}
    fid["bound"]["looks"] = 1
    one = DesignSearch(SPACE, [SIZE], SearchConfig(grid_points=3, seeds=1, fidelity=fid), REFS)
    assert "stop_at" not in one.job("bound", SIZE, d).fidelity
    # the optimizer's corrected bound is a continuous objective: it draws every capture
    search.ingest([fake_result(j) for j in search.suggest()])
    assert all("stop_at" not in j.fidelity for j in search.optimize_jobs())
    assert search.optimize_jobs() == optimize_jobs(search.evidence, lambda req, d: search.job("bound", req, d))


def test_a_learner_far_behind_after_its_first_seed_is_not_trained_again():
    """Learners stage: every candidate at seed 0, then more seeds only for those whose interval reaches the leader."""
    offsets = {"mlp": 0.03, "cnn1d": 0.0001, "knn": 0.0}   # loc: the MLP 3 cm behind, the CNN within reach

    def result(job):
        r = fake_result(job)
        if job.evaluator == "trained":
            m = job.fidelity["model"]
            extra = offsets[m] if job.task == "loc" else -10 * offsets[m]
            r.update(value=r["value"] + extra, lo=r["lo"] + extra, hi=r["hi"] + extra)
        return r

    search = DesignSearch(SPACE, [LOC, SIZE], SearchConfig(grid_points=3, refine_steps=0, seeds=3,
                                                           models=("mlp", "cnn1d", "knn")), REFS)
    asked = []
    while search.stage in (Stage.SCREEN, Stage.LEARNERS):
        jobs = search.suggest()
        asked += [j for j in jobs if j.evaluator == "trained" and j.design == search.evidence.base]
        search.ingest([result(j) for j in jobs])
    ev = search.evidence
    seeds = {(t, m): sum(j.task == t and j.fidelity["model"] == m for j in asked) for t in ("loc", "size") for m in offsets}
    assert seeds == {("loc", "mlp"): 1, ("loc", "cnn1d"): 3, ("loc", "knn"): 3,
                     ("size", "mlp"): 1, ("size", "cnn1d"): 3, ("size", "knn"): 3}
    assert ev.contenders(LOC) == ("cnn1d", "knn") and ev.learner("loc") == "knn" and ev.learner("size") == "knn"
    rows = {(r["task"], r["model"]): r for r in summarize(ev)["learners"]}
    assert rows[("loc", "mlp")]["seeds"] == 1 and not rows[("loc", "mlp")]["chosen"]
