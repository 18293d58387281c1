"""Ask/tell capture planner on a synthetic counts model: suggest/ingest, failures, budget, checkpoint and resume."""

import itertools
import json

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.planner.capture import CapturePlanner, PlannerConfig, fit_counts_model
from nlosplan.planner.capture.batch import batch_information
from nlosplan.planner.capture.calibration import DEFAULT_PRIOR_STD, prior_information
from nlosplan.planner.capture.space import CandidateSpace
from nlosplan.planner.capture.strategies import raster_order


BINS = 24


def synthetic_space(n: int = 5, repeats: int = 3, step: float = 80.0) -> CandidateSpace:
    """``n x n`` candidates (mm) whose object return is a Gaussian pulse; time and zone split encode (x, y)."""
    xs = np.arange(n) * step
    pts = np.array([(x, y) for y in xs for x in xs], dtype=np.float64)
    labels = pts / 1000.0 + np.array([1.0, 0.2])
    t = np.arange(BINS, dtype=np.float64)
    c = len(pts)
    direct = np.zeros((c, 2, BINS))
    direct[:, :, 2] = 5000.0
    floor = np.full((c, 2, BINS), 2.0)
    obj = np.zeros((c, 2, BINS))
    jac = np.zeros((c, 2, BINS, 2))
    for i, (x, y) in enumerate(labels):
        centre = 6.0 + 40.0 * (x - 1.0) + 20.0 * (y - 0.2)
        share = np.array([0.5 + (x - 1.16), 0.5 - (x - 1.16)])
        pulse = 400.0 * np.exp(-0.5 * (t - centre) ** 2)
        dpulse = pulse * (t - centre)               # d pulse / d centre
        obj[i] = share[:, None] * pulse[None]
        jac[i, :, :, 0] = share[:, None] * dpulse[None] * 40.0 + np.array([1.0, -1.0])[:, None] * pulse[None]
        jac[i, :, :, 1] = share[:, None] * dpulse[None] * 20.0
    return CandidateSpace(points_mm=pts, labels_xy=labels, direct=direct.reshape(c, -1), object=obj.reshape(c, -1),
                          floor=floor.reshape(c, -1), jac_xy=jac.reshape(c, 2 * BINS, 2),
                          shape=(1, 2, BINS), repeats=repeats, meta={"synthetic": True})


def observe(space, index, rng, theta=None):
    lam = space.counts(theta, [index])[0]
    return rng.poisson(np.broadcast_to(lam, (space.repeats,) + lam.shape)).mean(axis=0)


def run(planner, space, rng, rounds, fail=()):
    for _ in range(rounds):
        batch = planner.suggest()
        if not batch:
            break
        planner.ingest([{"id": p["id"], "error": "gantry alarm 2"} if p["index"] in fail else
                        {"id": p["id"], "histogram": observe(space, p["index"], rng)} for p in batch])


@pytest.mark.parametrize("strategy", ["random", "active", "active-motion", "doptimal", "doptimal-motion"])
def test_checkpoint_and_resume_give_the_same_next_batch(tmp_path, strategy):
    space = synthetic_space()
    a = CapturePlanner(space, PlannerConfig(strategy=strategy, batch_size=3, seed=4))
    run(a, space, np.random.default_rng(0), 2)
    path = a.save(tmp_path / "plan.json")
    b = CapturePlanner.load(path, space)
    assert json.loads(path.read_text())["format"] == "nlosplan-capture-planner/1"
    na, nb = a.suggest(), b.suggest()
    assert [p["index"] for p in na] == [p["index"] for p in nb]
    assert [p["id"] for p in na] == [p["id"] for p in nb]
    assert len({p["index"] for p in na} | {o["index"] for o in a.observations}) == 9  # no repeats
    np.testing.assert_allclose(a.calibration()["theta"], b.calibration()["theta"])


def test_failed_captures_are_recorded_retried_then_given_up():
    space = synthetic_space()
    planner = CapturePlanner(space, PlannerConfig(strategy="raster", batch_size=5))
    run(planner, space, np.random.default_rng(1), 12, fail={2})
    assert [f["index"] for f in planner.failures] == [2, 2]
    assert all(f["reason"] == "gantry alarm 2" for f in planner.failures)
    assert 2 not in planner.captured and len(planner.captured) == space.size - 1
    assert planner.finished == "no candidate positions left"
    assert planner.suggest() == []


def test_budget_stops_the_planner_with_a_reason():
    space = synthetic_space()
    planner = CapturePlanner(space, PlannerConfig(strategy="active", batch_size=4, budget=6))
    first = planner.suggest()
    assert len(first) == 4
    planner.ingest([{"id": p["id"], "histogram": observe(space, p["index"], np.random.default_rng(2))} for p in first])
    second = planner.suggest()
    assert len(second) == 2  # cut to the budget left
    assert planner.suggest() == [] and planner.finished is None  # pending captures: not finished yet
    planner.ingest([{"id": p["id"], "histogram": observe(space, p["index"], np.random.default_rng(3))} for p in second])
    assert planner.suggest() == [] and planner.finished == "budget of 6 captures spent"
    assert planner.best()["captures"] == 6


def test_ingest_rejects_unknown_ids_twice_ingested_and_bad_histograms():
    space = synthetic_space()
    planner = CapturePlanner(space, PlannerConfig(strategy="random", batch_size=2))
    batch = planner.suggest()
    with pytest.raises(UserError, match="capture id 'nope' was not proposed"):
        planner.ingest([{"id": "nope", "histogram": np.zeros(48)}])
    with pytest.raises(UserError, match="histogram must hold 48 finite counts, got 3"):
        planner.ingest([{"id": batch[0]["id"], "histogram": [1, 2, 3]}])
    planner.ingest([{"id": batch[0]["id"], "histogram": np.ones(48)}])
    with pytest.raises(UserError, match="already ingested"):
        planner.ingest([{"id": batch[0]["id"], "histogram": np.ones(48)}])


def test_resume_refuses_other_candidates_and_other_files(tmp_path):
    space = synthetic_space()
    path = CapturePlanner(space, PlannerConfig(strategy="random")).save(tmp_path / "p.json")
    with pytest.raises(UserError, match="other candidate positions"):
        CapturePlanner.load(path, synthetic_space(n=4))
    (tmp_path / "x.json").write_text("{}")
    with pytest.raises(UserError, match="not a capture-planner checkpoint"):
        CapturePlanner.load(tmp_path / "x.json", space)
    with pytest.raises(UserError, match="unknown planner strategy 'best'"):
        PlannerConfig(strategy="best")


def test_raster_is_a_snake_and_the_route_of_other_batches_starts_near_the_gantry():
    space = synthetic_space(n=3)
    order = raster_order(space.points_mm)
    # DENALI's order: x is the slow axis, y runs up the first column and back down the next
    assert space.points_mm[order].tolist() == [[0, 0], [0, 80], [0, 160], [80, 160], [80, 80], [80, 0],
                                               [160, 0], [160, 80], [160, 160]]
    planner = CapturePlanner(space, PlannerConfig(strategy="random", batch_size=9, seed=3))
    batch = planner.suggest()
    assert batch[0]["x_mm"] + batch[0]["y_mm"] <= 80  # nearest neighbour from (0, 0) first


def test_calibration_fit_recovers_the_truth_and_doptimal_beats_raster_early():
    space = synthetic_space()
    truth = np.array([0.002, -0.001, 0.05, -0.1])
    rng = np.random.default_rng(5)
    idx = np.arange(space.size)
    obs = np.array([observe(space, i, rng, truth) for i in idx])
    fit = fit_counts_model(space, idx, obs)
    assert np.all(np.abs(fit["theta"] - truth) <= 4 * fit["std"])
    assert fit["identifiable"]
    # the first batch of 4 by its information about the calibration at the nominal point (what doptimal
    # maximises; the Fisher after the fit depends on the noise draw): doptimal's is the best of all 12,650
    # batches, DENALI's raster (the first column, y running) falls short of it
    fishers, prior = space.fisher(np.zeros(4)), prior_information(DEFAULT_PRIOR_STD)
    info = {}
    for strategy in ("raster", "doptimal"):
        planner = CapturePlanner(space, PlannerConfig(strategy=strategy, batch_size=4))
        info[strategy] = batch_information([p["index"] for p in planner.suggest()], fishers, prior)
    best = max(batch_information(b, fishers, prior) for b in itertools.combinations(range(space.size), 4))
    assert info["doptimal"] == pytest.approx(best, abs=1e-9) and info["doptimal"] > info["raster"] + 1e-4
