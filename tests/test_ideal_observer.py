"""Ideal-observer classification: exact toy error rates, intervals, photons, known vs unknown position."""

import math

import numpy as np
import pytest
from scipy import stats

from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.tasks.ideal_observer import binomial_interval, ideal_observer, observer_accuracy

SENSOR = preset("tmf8828-3x3-short")
OBJECTS = ["A", "B", "circle", "7"]
POSITIONS = [0, 19, 50, 99]
FID = "draft"


def shape(sensor=SENSOR, **kw):
    return ideal_observer("shape", sensor, objects=OBJECTS, positions=POSITIONS, fidelity=FID, **kw)


# ----------------------------------------------------------------------------- toy model with a known error rate
LAM0, LAM1 = 5.0, 10.0  # one bin; decide class 1 when y log 2 > 5, i.e. y >= 8
TRUE_ACCURACY = 1.0 - 0.5 * (stats.poisson.sf(7, LAM0) + stats.poisson.cdf(7, LAM1))
TOY = np.array([[[LAM0]], [[LAM1]]])


def test_toy_accuracy_matches_the_exact_rate_and_the_interval_covers_it():
    hits, widths = 0, {}
    for seed in range(200):
        out = observer_accuracy(TOY, [0, 1], draws=200, seed=seed)
        lo, hi = out["ci"]
        hits += lo <= TRUE_ACCURACY <= hi
    assert hits / 200 >= 0.9  # nominal 95 %
    for draws in (100, 1600):
        widths[draws] = np.mean([np.subtract(*observer_accuracy(TOY, [0, 1], draws=draws, seed=s)["ci"][::-1])
                                 for s in range(20)])
    assert widths[100] / widths[1600] == pytest.approx(4.0, rel=0.1)  # ~ 1 / sqrt(draws)
    big = observer_accuracy(TOY, [0, 1], draws=20000, seed=1)
    assert big["accuracy"] == pytest.approx(TRUE_ACCURACY, abs=0.01)
    assert big["confusion"].sum() == 40000 and big["confusion"].sum(axis=1).tolist() == [20000, 20000]


def test_bins_equal_under_every_hypothesis_change_nothing():
    # a floor and a direct peak the same in every hypothesis and position (most of a real histogram) carry no
    # information: with them the observer decides exactly as without them, capture for capture
    rng = np.random.default_rng(3)
    cube = 20.0 + rng.normal(0.0, 1.0, (4, 3, 16))
    common = np.concatenate([np.full(200, 1200.0), np.linspace(3e4, 10.0, 40)])
    padded = np.concatenate([np.broadcast_to(common, (4, 3, common.size)), cube], axis=2)
    a = observer_accuracy(cube, [0, 0, 1, 1], draws=300, seed=5)
    b = observer_accuracy(padded, [0, 0, 1, 1], draws=300, seed=5)
    assert np.array_equal(a["decision"], b["decision"]) and a["accuracy"] == b["accuracy"]
    assert 0.5 < a["accuracy"] < 1.0
    # one bin that differs between hypotheses is used
    informative = padded.copy()
    informative[2:, :, 0] = 1500.0
    assert observer_accuracy(informative, [0, 0, 1, 1], draws=300, seed=5)["accuracy"] > 0.99


def test_the_float32_product_decides_as_float64():
    # DENALI-like counts: a floor of ~1e3 per bin (the real one) under small object signals, 8 hypotheses in 4
    # classes at 6 positions; the centred float32 product must take float64's decision for every capture
    rng = np.random.default_rng(11)
    floor = np.concatenate([np.full(60, 1000.0), 3e4 * np.exp(-np.arange(20) / 3.0), np.full(220, 1000.0)])
    signal = np.abs(rng.normal(0.0, 4.0, (8, 6, floor.size))) * (np.arange(floor.size) > 80)
    cube = floor + signal
    cls = [0, 0, 1, 1, 2, 2, 3, 3]
    a = observer_accuracy(cube, cls, draws=600, seed=2, precision="float64")
    b = observer_accuracy(cube, cls, draws=600, seed=2)
    assert 0.3 < a["accuracy"] < 0.95  # neither trivial nor hopeless: decisions are close calls
    assert np.array_equal(a["decision"], b["decision"])
    with pytest.raises(UserError, match="unknown precision 'float16'"):
        observer_accuracy(cube, cls, draws=10, precision="float16")


def test_toy_observer_is_deterministic_for_a_seed():
    a = observer_accuracy(TOY, [0, 1], draws=50, seed=7)
    b = observer_accuracy(TOY, [0, 1], draws=50, seed=7)
    assert a["accuracy"] == b["accuracy"] and np.array_equal(a["decision"], b["decision"])


def test_binomial_intervals():
    lo, hi = binomial_interval(50, 100)
    assert lo < 0.5 < hi and hi - lo == pytest.approx(2 * 1.96 * 0.05, rel=0.05)
    assert binomial_interval(0, 20)[0] == 0.0 and binomial_interval(20, 20)[1] == 1.0
    cp = binomial_interval(3, 30, method="clopper-pearson")
    assert cp[0] <= binomial_interval(3, 30)[0] and cp[1] >= binomial_interval(3, 30)[1]  # exact is conservative
    with pytest.raises(UserError, match="unknown interval method 'bayes'"):
        binomial_interval(1, 2, method="bayes")


def test_identical_classes_are_ties_broken_at_random():
    out = observer_accuracy(np.full((3, 2, 4), 6.0), [0, 1, 2], draws=3000, seed=0)
    assert out["accuracy"] == pytest.approx(1 / 3, abs=0.03)
    assert np.all(out["confusion"].sum(axis=0) > 2500)  # every decision is taken, not always the first
    # the same with informative bins (positions differ) in both precisions of the product
    per_position = 1000.0 + 50.0 * np.random.default_rng(4).random((5, 700))
    cube = np.broadcast_to(per_position, (3, 5, 700))
    for precision in ("float32", "float64"):
        out = observer_accuracy(cube, [0, 1, 2], draws=3000, seed=0, precision=precision)
        assert out["accuracy"] == pytest.approx(1 / 3, abs=0.03)
        assert np.all(out["confusion"].sum(axis=0) > 2500)


# ----------------------------------------------------------------------------- DENALI
def test_noise_free_captures_are_always_right():
    for kw in ({}, {"position_known": True}, {"rule": "max"}):
        r = shape(draws=8, noise=False, **kw)
        assert r.accuracy == 1.0 and np.all(np.diag(r.confusion) == 8)
    size = ideal_observer("size", SENSOR, objects=["A", "circle"], positions=[19, 50], fidelity=FID, draws=8,
                          noise=False)
    assert size.classes == ("4in", "8in") and size.accuracy == 1.0


def test_accuracy_falls_with_photons_to_chance():
    acc = [shape(SENSOR.replace(iterations=int(SENSOR.iterations * k)), draws=200).accuracy for k in (1, 0.01, 0.001)]
    assert acc[0] > 0.97 and acc[0] > acc[1] + 0.1 and acc[1] > acc[2] + 0.1
    dark = shape(SENSOR.replace(photon_scale=0.0), draws=200, seed=1)
    lo, hi = dark.ci
    assert lo <= dark.chance <= hi and dark.chance == 0.25


def test_known_position_is_at_least_as_accurate():
    weak = SENSOR.replace(iterations=int(SENSOR.iterations * 0.002))
    for seed in (0, 1):
        unknown = shape(weak, draws=400, seed=seed)
        known = shape(weak, draws=400, seed=seed, position_known=True)  # same captures (same seed)
        assert known.accuracy >= unknown.accuracy
        assert 0.3 < unknown.accuracy < 0.9


def test_result_records_fidelity_time_and_counts():
    r = shape(draws=10)
    assert r.draws == 10 and r.n == 40 and r.confusion.sum() == 40 and r.per_class_accuracy.shape == (4,)
    assert r.fidelity == "draft" and r.knobs["object_samples"] == 64
    assert 0 < r.seconds_simulation <= r.seconds and r.seed == 0
    assert r.classes == tuple(OBJECTS) and r.meta["positions"] == POSITIONS
    assert "accuracy" in r.summary() and math.isclose(r.error_rate, 1 - r.accuracy)


def test_bad_inputs_are_user_errors():
    with pytest.raises(UserError, match="task"):
        ideal_observer("colour", SENSOR)
    with pytest.raises(UserError, match="rule"):
        observer_accuracy(TOY, [0, 1], draws=5, rule="mean")
    with pytest.raises(UserError, match="draws"):
        observer_accuracy(TOY, [0, 1], draws=0)
    with pytest.raises(UserError, match="at least two"):
        ideal_observer("shape", SENSOR, objects=["A"])


# ----------------------------------------------------------------------------- stopping once clear of a threshold
def test_the_observer_stops_after_a_round_far_from_every_threshold():
    full = observer_accuracy(TOY, [0, 1], draws=400, seed=3)
    assert full["draws"] == 400 and not full["stopped_early"] and full["n"] == 800
    # the toy's accuracy is ~0.83: thresholds 0.5 and 0.99 are both far outside a round's 99.9 % interval
    early = observer_accuracy(TOY, [0, 1], draws=400, seed=3, stop_at=[0.5, 0.99], looks=4)
    assert early["stopped_early"] and early["draws"] == 100 and early["n"] == 200
    assert early["confusion"].sum(axis=1).tolist() == [100, 100]  # every round is stratified over the classes
    assert early["truth"].size == early["decision"].size == 200
    assert early["accuracy"] == pytest.approx(TRUE_ACCURACY, abs=0.08)
    assert early["ci"][0] <= TRUE_ACCURACY <= early["ci"][1]
    # a threshold at the accuracy itself never clears: every draw is made
    close = observer_accuracy(TOY, [0, 1], draws=400, seed=3, stop_at=[TRUE_ACCURACY], looks=4)
    assert not close["stopped_early"] and close["draws"] == 400 and close["n"] == 800
    # one look is the full run, whatever the thresholds
    one = observer_accuracy(TOY, [0, 1], draws=400, seed=3, stop_at=[0.5], looks=1)
    assert one["draws"] == 400 and not one["stopped_early"]
    # draws not divisible by the looks: rounds of ceil(draws / looks)
    odd = observer_accuracy(TOY, [0, 1], draws=10, seed=3, stop_at=[0.01], looks=3)
    assert odd["draws"] in (4, 8, 10) and odd["n"] == 2 * odd["draws"]


def test_an_early_stop_lands_on_the_side_of_the_threshold_a_full_run_takes():
    # threshold 0.76 is ~7 % under the toy's accuracy: decided from a round of 100 draws per class in most seeds,
    # and every stopped run says "above", as the full runs do
    stopped = 0
    for seed in range(40):
        full = observer_accuracy(TOY, [0, 1], draws=400, seed=seed)
        early = observer_accuracy(TOY, [0, 1], draws=400, seed=seed, stop_at=[0.76], looks=4)
        assert full["ci"][0] > 0.76
        if early["stopped_early"]:
            stopped += 1
            assert early["ci"][0] > 0.76
    assert stopped >= 20


def test_looks_without_thresholds_change_nothing():
    a = observer_accuracy(TOY, [0, 1], draws=300, seed=9)
    b = observer_accuracy(TOY, [0, 1], draws=300, seed=9, looks=4)
    assert np.array_equal(a["decision"], b["decision"]) and np.array_equal(a["truth"], b["truth"])


def test_bad_stopping_knobs_are_user_errors():
    with pytest.raises(UserError, match="looks=0 must be >= 1"):
        observer_accuracy(TOY, [0, 1], draws=5, stop_at=[0.5], looks=0)
    with pytest.raises(UserError, match=r"stop_confidence=1.5 must be in \(0, 1\)"):
        observer_accuracy(TOY, [0, 1], draws=5, stop_at=[0.5], stop_confidence=1.5)
    with pytest.raises(UserError, match="stop_at must be finite"):
        observer_accuracy(TOY, [0, 1], draws=5, stop_at=[float("nan")])
