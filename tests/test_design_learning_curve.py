"""The learner's learning curve at the reference design (issue 36: the training budget as an input, DENALI's 25,200
captures at DENALI's point): the ladder of budgets, the search's jobs, the evidence keeping them apart from the run's
own runs, ``denali_point`` predicting at DENALI's budget, the report's sentence and the consistency check. On the
analytic stand-in of the evaluators (``test_design_verdicts``): no simulation, no training."""

from __future__ import annotations

import math

import pytest

from nlosplan.errors import UserError
from nlosplan.planner.design.config import full_config, load_config, quick_config
from nlosplan.planner.design.evaluation import Evaluator
from nlosplan.planner.design.learning_curve import (DENALI_TRAIN_CAPTURES, curve_budgets, curve_summary,
                                                    run_budget)
from nlosplan.planner.design.requirements import Requirement
from nlosplan.planner.design.search import DesignSearch, SearchConfig
from nlosplan.planner.design.summary import summarize
from nlosplan.reports.denali_section import curve_text, denali_point_table, denali_point_text, trained_verdict
from test_design_verdicts import REFS, SPACE, Fake, drive

LOC, SIZE = Requirement("loc", 0.05), Requirement("size", 0.9)
RUN_BUDGET = 2100


class Curve(Fake):
    """The stand-in with a training budget: ``n_train`` as asked (2,100 by default); more captures help
    (localization error times ``(2100 / n) ** 0.2``, accuracy plus 2 points per doubling), or hurt with
    ``sign=-1``."""

    def __init__(self, sign: int = 1, beat_bound_at: int | None = None):
        super().__init__()
        self.sign, self.beat_bound_at = sign, beat_bound_at

    def __call__(self, job):
        r = super().__call__(job)
        if job.evaluator == "bound":
            return r
        n = int(job.fidelity.get("train_captures", RUN_BUDGET))
        r["extra"] = {"n_train": n}
        if job.task == "loc":
            f = (RUN_BUDGET / n) ** (0.2 * self.sign)
            if self.beat_bound_at == n:
                f = 0.05
            r.update(value=r["value"] * f, lo=r["lo"] * f, hi=r["hi"] * f)
        else:
            d = self.sign * 0.02 * math.log2(n / RUN_BUDGET)
            r.update(value=min(r["value"] + d, 0.999), lo=min(r["lo"] + d, 0.999), hi=min(r["hi"] + d, 0.999))
        return r


def _search(fake, curve_seeds: int = 2, real: bool = False):
    cfg = SearchConfig(grid_points=3, refine_steps=0, seeds=2, models=("mlp", "cnn1d"), curve_seeds=curve_seeds)
    trained = {k: f"real_{v}" for k, v in REFS.items()} if real else None
    search = DesignSearch(SPACE, [LOC, SIZE], cfg, REFS, trained_references=trained)
    return search, drive(search, fake)


def test_the_ladder_reaches_denali_s_budget_from_a_quarter_of_the_run_s():
    assert DENALI_TRAIN_CAPTURES == 25_200  # 70 % of DENALI's 36,000 captures
    assert curve_budgets(2100) == [525, 1050, 8400, 25200]
    assert curve_budgets(700) == [175, 350, 2800, 25200]
    assert curve_budgets(8000) == [2000, 4000, 25200]  # four times it is past DENALI's: not measured
    assert curve_budgets(25200) == [6300, 12600] and curve_budgets(30000) == [7500, 15000]
    # real captures cannot be drawn again: nothing above the run's budget
    assert curve_budgets(2100, real=True) == [525, 1050]
    assert curve_budgets(3) == [12, 25200]  # a quarter and a half are below a learner's two captures


def test_the_search_trains_the_learner_on_every_budget_at_the_reference_design_only():
    search, calls = _search(Curve())
    ev = search.evidence
    jobs = [j for j in calls if j.evaluator is Evaluator.LEARNING_CURVE]
    assert {j.design for j in jobs} == {ev.base}
    for req in (LOC, SIZE):
        mine = [j for j in jobs if j.task == req.task]
        assert sorted((j.fidelity["train_captures"], j.seed) for j in mine) == sorted(
            (n, ev.config.seed_of(i)) for n in (525, 1050, 8400, 25200) for i in range(2))
        assert {j.fidelity["model"] for j in mine} == {ev.learner(req.task)}
        assert run_budget(ev, req) == RUN_BUDGET
        # the curve's runs do not stand in for the run's own: the same seed, another cell
        own = ev.run(Evaluator.TRAINED, req, ev.base, 0)
        at = ev.run(Evaluator.LEARNING_CURVE, req, ev.base, 0, budget=25200)
        assert own.extra["n_train"] == RUN_BUDGET and at.extra["n_train"] == 25200 and own.seed == at.seed
        assert ev.trained_value(req, ev.base).seeds == len(ev.runs(req, ev.base))
    # no curve asked (the bare search's default): no such job
    assert not [j for j in _search(Curve(), curve_seeds=0)[1] if j.evaluator is Evaluator.LEARNING_CURVE]
    # with real captures the ladder stops at the run's budget
    real = [j for j in _search(Curve(), real=True)[1] if j.evaluator is Evaluator.LEARNING_CURVE]
    assert {j.fidelity["train_captures"] for j in real} == {525, 1050}
    assert {j.reference for j in real} == {"real_ref3.npz"}


def test_denali_s_point_is_predicted_at_denali_s_budget_with_the_run_s_beside_it():
    search, _ = _search(Curve())
    ev = search.evidence
    res = summarize(ev)
    rows = {r["task"]: r for r in res["denali_point"]}
    for req in (LOC, SIZE):
        row, own = rows[req.task], ev.trained_value(req, ev.base)
        assert row["evaluator"] == "learning_curve" and row["train_captures"] == 25200 and row["seeds"] == 2
        assert row["run_budget"]["train_captures"] == RUN_BUDGET
        assert row["run_budget"]["value"] == pytest.approx(own.value) and row["run_budget"]["verdict"] == own.verdict
        curve = row["learning_curve"]
        assert [c["train_captures"] for c in curve] == [525, 1050, 2100, 8400, 25200]
        assert [c["run_budget"] for c in curve] == [False, False, True, False, False]
        assert curve[-1]["value"] == pytest.approx(row["predicted"]) and row["conservative"] is True
    # the stand-in's localization error shrinks as (2100 / n) ** 0.2
    loc = rows["loc"]
    assert loc["predicted"] / loc["run_budget"]["value"] == pytest.approx((2100 / 25200) ** 0.2, rel=1e-6)
    assert loc["curve_gain"] == pytest.approx(loc["predicted"] - loc["run_budget"]["value"])
    assert rows["size"]["curve_gain"] == pytest.approx(0.0)  # the stand-in's accuracy is at its 0.999 ceiling
    assert trained_verdict(loc).endswith("trained on 25,200 captures")
    assert "25,200 simulated training" in denali_point_table(res).set_index("requirement").loc[LOC.name, "learner"]
    text = curve_text(res)
    assert "2,100 (the run's budget)" in text and "none extrapolated" in text and "DENALI's Table 1 budget" in text
    assert "look conservative" in text and "made the learner worse" not in text
    assert text in denali_point_text(res)
    assert res["consistency"] == []


class AtTheThreshold(Curve):
    """Size accuracy exactly at 0.9 (+-0.04) at DENALI's budget: undecided however many seeds."""

    def __call__(self, job):
        r = super().__call__(job)
        if job.task == "size" and job.fidelity.get("train_captures") == 25200:
            r.update(value=0.9, lo=0.86, hi=0.94)
        return r


def test_an_undecided_point_at_denali_s_budget_gets_seeds_as_a_candidate_does():
    search, calls = _search(AtTheThreshold())
    ev = search.evidence
    at = [j for j in calls if j.evaluator is Evaluator.LEARNING_CURVE and j.fidelity["train_captures"] == 25200]
    size = [j.seed - ev.config.seed_of(0) for j in at if j.task == "size"]
    assert sorted(size) == list(range(ev.config.max_seeds))  # two per round up to max_seeds, while undecided
    assert sorted(j.seed - ev.config.seed_of(0) for j in at if j.task == "loc") == [0, 1]  # met: no more
    row = next(r for r in summarize(ev)["denali_point"] if r["task"] == "size")
    assert row["seeds"] == ev.config.max_seeds and row["verdict"] == "undecided" and row["predicted"] == 0.9


def test_a_curve_that_gets_worse_with_more_captures_is_said_so():
    res = summarize(_search(Curve(sign=-1))[0].evidence)
    assert {r["conservative"] for r in res["denali_point"]} == {False}
    text = curve_text(res)
    assert "More captures made the learner worse for loc loc_rmse <= 0.05 m, size top1_acc >= 0.9" in text
    assert "may promise more than DENALI's budget gives" in text and "conservative" not in text


def test_without_a_curve_the_point_is_the_run_s_own_budget():
    ev = _search(Curve(), curve_seeds=0)[0].evidence
    res = summarize(ev)
    for row in res["denali_point"]:
        assert row["evaluator"] == "trained" and row["train_captures"] == RUN_BUDGET
        assert [c["train_captures"] for c in row["learning_curve"]] == [RUN_BUDGET] and row["conservative"] is None
    assert "Learning curves" in curve_text(res) and "DENALI's Table 1 budget" not in curve_text(res)


def test_a_curve_point_beyond_its_bound_is_flagged():
    res = summarize(_search(Curve(beat_bound_at=25200))[0].evidence)
    flagged = [f for f in res["consistency"] if f["task"] == "loc"]
    assert [f["learner"] for f in flagged] == ["mlp on 25,200 captures"]
    assert "wholly below the Cramér–Rao bound" in flagged[0]["issue"]
    # the same estimate as the curve's point (every seed it has)
    point = next(r for r in res["denali_point"] if r["task"] == "loc")["learning_curve"][-1]
    assert (flagged[0]["value"], flagged[0]["seeds"]) == (pytest.approx(point["value"]), point["seeds"])


def test_curve_summary_compares_the_largest_budget_with_the_run_s():
    from test_design_denali_point import est

    from nlosplan.planner.design.verdicts import MET

    own, more = est(0.06, 0.05, 0.07, MET), est(0.065, 0.058, 0.072, MET)
    said = curve_summary(LOC, [(100, own, True), (400, more, False)])
    assert said.conservative is True and said.gain == pytest.approx(0.005) and said.at_target is None
    worse = est(0.08, 0.075, 0.085, MET)  # its whole interval is worse than the run's figure
    assert curve_summary(LOC, [(100, own, True), (400, worse, False)]).conservative is False
    assert curve_summary(LOC, [(100, own, True), (25200, more, False)]).at_target is more
    assert curve_summary(LOC, [(100, own, True)]).conservative is None and curve_summary(LOC, []).gain is None


def test_the_main_job_and_quick_train_the_curve_and_a_toml_sets_its_seeds(tmp_path):
    assert full_config().search.curve_seeds == 2 and quick_config().search.curve_seeds == 1
    assert SearchConfig().curve_seeds == 0
    p = tmp_path / "c.toml"
    p.write_text("[search]\ncurve_seeds = 0\n")
    assert load_config(p, full_config()).search.curve_seeds == 0
    p.write_text("[search]\ncurve_seeds = -1\n")
    with pytest.raises(UserError, match="curve_seeds"):
        load_config(p, full_config())
    with pytest.raises(UserError, match=r"curve_seeds=-1 must be a whole number >= 0"):
        SearchConfig(curve_seeds=-1)


def test_the_report_draws_the_curves_and_none_without_them(tmp_path):
    from nlosplan.reports.design_plots import plot_learning_curves

    res = summarize(_search(Curve())[0].evidence)
    path = plot_learning_curves(res, tmp_path / "lc.png")
    assert path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and path.stat().st_size > 10_000
    bare = summarize(_search(Curve(), curve_seeds=0)[0].evidence)  # one point per curve: nothing to draw
    assert plot_learning_curves(bare, tmp_path / "none.png") is None and not (tmp_path / "none.png").exists()
