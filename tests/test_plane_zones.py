"""The all-zone plane model: recovery of known terms from simulated captures, scores, cross-validation folds."""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.sensor_models import SensorConfig, preset
from nlosplan.calibration.plane_cv import distance_folds, jackknife
from nlosplan.calibration.plane_fit import fit_plane_zones, zone_sensor
from nlosplan.calibration.plane_model import check_terms
from nlosplan.calibration.plane_scores import predict_plane, score_plane, subbin_peak
from nlosplan.calibration.tmf882x_fit import DistanceCaptures
from nlosplan.simulators import WallScene, wall_arrivals

TRUTH = dict(zone_gains=(0.7, 1.3, 0.9, 1.1), zone_time_offsets_ps=(-40.0, 30.0, 0.0, 10.0),
             zone_time_scales=(0.99, 1.01, 1.0, 1.0), zone_overlap_m=(0.03, 0.08, 0.05, 0.0),
             pileup=True, iterations=4_000_000, time_walk_ps=60.0, pulse_tail_fraction=0.002,
             pulse_tail_decay_ps=1500.0)


def _truth() -> SensorConfig:
    base = preset("tmf8828-4x4-short")
    return base.replace(name="truth", zones_rows=2, zones_cols=2, fov_x_deg=33.0, fov_y_deg=32.0,
                        photon_scale=0.3, ambient_rate_hz=0.0, dark_rate_hz=0.0, **TRUTH)


def _arrivals(sensor):
    def arrivals(d):
        t, w = wall_arrivals(WallScene(distance_m=float(d), albedo=1.0), sensor, n_sub=3)
        return t.reshape(sensor.n_zones, -1), w.reshape(sensor.n_zones, -1)

    return arrivals


@pytest.fixture(scope="module")
def simulated():
    truth = _truth()
    dist = np.linspace(0.06, 0.4, 14)
    arr = _arrivals(truth)
    t, w = zip(*(arr(d) for d in dist))
    floor = np.linspace(40.0, 180.0, dist.size)[:, None] * np.ones((1, truth.n_zones))
    mean = predict_plane(truth, np.stack(t), np.stack(w), floor)
    counts = np.random.default_rng(3).poisson(mean).astype(np.float64)
    return truth, DistanceCaptures(dist, counts, np.zeros((dist.size, counts.shape[-1])))


@pytest.fixture(scope="module")
def recovered(simulated):
    truth, caps = simulated
    start = truth.replace(zone_gains=None, zone_time_offsets_ps=None, zone_time_scales=None, zone_overlap_m=None,
                          time_walk_ps=0.0, pileup=False, pulse_tail_fraction=0.0, iterations=550_000)
    return fit_plane_zones(caps, _arrivals(start), start), start


@pytest.mark.slow
def test_recovers_every_term_from_simulated_plane_captures(simulated, recovered):
    truth, _ = simulated
    fit, start = recovered
    v = fit.values
    assert fit.converged and fit.deviance < 2.0  # Poisson captures of the model itself: deviance ~ 1 per bin
    np.testing.assert_allclose(v["zone_gains"] / np.exp(np.mean(np.log(v["zone_gains"]))),
                               np.array(TRUTH["zone_gains"]) / np.exp(np.mean(np.log(TRUTH["zone_gains"]))), rtol=0.03)
    off = np.array(TRUTH["zone_time_offsets_ps"])
    np.testing.assert_allclose(np.array(v["zone_time_offsets_ps"]) - np.mean(v["zone_time_offsets_ps"]),
                               off - off.mean(), atol=8.0)
    np.testing.assert_allclose(v["zone_time_scales"], TRUTH["zone_time_scales"], atol=3e-3)
    np.testing.assert_allclose(v["zone_overlap_m"][:3], TRUTH["zone_overlap_m"][:3], rtol=0.1)
    assert v["zone_overlap_m"][3] < 0.015
    assert v["iterations"] == pytest.approx(TRUTH["iterations"], rel=0.05)
    assert v["time_walk_ps"] == pytest.approx(TRUTH["time_walk_ps"], abs=15.0)
    assert v["pulse_tail_fraction"] == pytest.approx(TRUTH["pulse_tail_fraction"], rel=0.5)
    # the fitted sensor file predicts the captures through the simulator's own pipeline
    rows, _ = score_plane(zone_sensor(start, fit), simulated[1], _arrivals(start))
    assert max(r.subbin_err_mean for r in rows) < 0.05 and max(r.l1_max for r in rows) < 0.05
    assert all(0.97 < r.amp_ratio_min and r.amp_ratio_max < 1.03 for r in rows)


def test_the_true_sensor_scores_perfectly_and_a_neutral_one_does_not(simulated):
    truth, caps = simulated
    rows, per = score_plane(truth, caps, _arrivals(truth))
    assert len(rows) == 4 and len(per["distance_m"]) == 14
    for r in rows:  # Poisson noise only
        assert r.subbin_err_mean < 0.03 and r.l1_mean < 0.02 and 0.98 < r.amp_ratio_min <= r.amp_ratio_max < 1.02
    flat = truth.replace(zone_gains=None, zone_time_offsets_ps=None, zone_overlap_m=None)
    rows, _ = score_plane(flat, caps, _arrivals(flat))
    assert rows[0].subbin_err_mean > 0.15 and rows[0].l1_mean > 0.1 and rows[0].amp_ratio_max > 1.3


def test_subbin_peak_interpolates_a_gaussian_exactly():
    x = np.arange(40) + 0.5
    for mu in (17.2, 17.5, 18.9):
        h = np.exp(-0.5 * ((x - mu) / 1.3) ** 2)
        assert subbin_peak(h) == pytest.approx(mu, abs=1e-9)


def test_folds_interleave_distances_and_jackknife_is_zero_for_equal_fits():
    d = np.array([0.3, 0.1, 0.2, 0.4, 0.05, 0.25])
    folds = distance_folds(d, np.arange(6), 3)
    assert [sorted(d[f].tolist()) for f in folds] == [[0.05, 0.25], [0.1, 0.3], [0.2, 0.4]]
    same = [{"bin_width_ps": 92.0, "zone_gains": [1.0, 2.0]}] * 3
    assert jackknife(same) == {"bin_width_ps": 0.0, "zone_gains": [0.0, 0.0]}
    spread = jackknife([{"bin_width_ps": 90.0}, {"bin_width_ps": 92.0}])
    assert spread["bin_width_ps"] == pytest.approx(1.0)  # sqrt(1/2 * (1 + 1))


def test_unknown_terms_and_too_few_captures_are_one_line_errors(simulated):
    with pytest.raises(UserError, match="unknown plane-model term"):
        check_terms(["offsets", "magic"])
    truth, caps = simulated
    with pytest.raises(UserError, match="needs >= 3 captures"):
        fit_plane_zones(caps, _arrivals(truth), truth, indices=[0, 1])


def test_a_fit_stopped_by_its_budget_says_so_with_its_best_objective(simulated):
    truth, caps = simulated
    fit = fit_plane_zones(caps, _arrivals(truth), truth, terms=("offsets", "gains"), max_evals=(3, 3, 3))
    assert not fit.converged
    assert any("did not converge within 3 evaluations" in m and f"best mean deviance {fit.deviance:.4g}" in m
               for m in fit.messages)
