"""Calibration recovers known parameters from simulated captures and fails loudly on bad input."""

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.sensor_models import SensorConfig, load_sensor_file
from nlosplan.calibration import CaptureSet, calibrated_sensor, fit_sensor_model, usable_zones
from nlosplan.sensor_models.pipeline import expected_histogram
from nlosplan.simulators import WallScene, wall_arrivals

TRUE = {"photon_scale": 2.0, "pulse_fwhm_ps": 250.0, "bin_width_ps": 91.0, "start_offset_ps": -1150.0,
        "crosstalk": 2e-4}
FLOOR = 40.0  # counts per bin
ITERS = 550_000
DISTANCES = np.linspace(0.08, 0.4, 12)


def _sensor(**kw):
    v = {**TRUE, **kw}
    rate = FLOOR / (ITERS * v["bin_width_ps"] * 1e-12)
    return SensorConfig(zones_rows=3, zones_cols=3, n_bins=128, bin_width_ps=v["bin_width_ps"],
                        start_offset_ps=v["start_offset_ps"], pulse_fwhm_ps=v["pulse_fwhm_ps"],
                        photon_scale=v["photon_scale"], iterations=ITERS, dark_rate_hz=rate, crosstalk=v["crosstalk"],
                        saturation=False)


def _captures(seed=0, zones=(4,)):
    """Poisson captures of a plane at known distances, made by the sensor pipeline (independent of the fit model)."""
    s = _sensor()
    rng = np.random.default_rng(seed)
    counts, times, weights = [], [], []
    for d in DISTANCES:
        t, w = wall_arrivals(WallScene(distance_m=float(d), albedo=1.0), s)
        t, w = t.reshape(9, -1)[list(zones)], w.reshape(9, -1)[list(zones)]
        mu = np.asarray(expected_histogram(s, t, w, lights_on=False))
        counts.append(rng.poisson(mu))
        times.append(t)
        weights.append(w)
    return CaptureSet(np.array(counts, dtype=np.float64), np.array(times), np.array(weights), ITERS,
                      tuple(f"{d:.2f} m" for d in DISTANCES))


@pytest.fixture(scope="module")
def simulated():
    return _captures()


@pytest.fixture(scope="module")
def recovered(simulated):
    start = {"bin_width_ps": 94.0, "start_offset_ps": -1100.0, "pulse_fwhm_ps": 150.0}
    return fit_sensor_model(simulated, start=start, noise="global")


def test_recovers_known_parameters_within_their_uncertainties(recovered):
    v, e = recovered.values, recovered.errors
    assert set(recovered.fitted) == {"photon_scale", "pulse_fwhm_ps", "bin_width_ps", "start_offset_ps",
                                     "floor_counts", "crosstalk"}
    assert v["photon_scale"] == pytest.approx(TRUE["photon_scale"], rel=0.005)
    assert v["pulse_fwhm_ps"] == pytest.approx(TRUE["pulse_fwhm_ps"], rel=0.02)
    assert v["bin_width_ps"] == pytest.approx(TRUE["bin_width_ps"], abs=0.1)
    assert v["start_offset_ps"] == pytest.approx(TRUE["start_offset_ps"], abs=3.0)
    assert v["floor_counts"] == pytest.approx(FLOOR, rel=0.02)
    assert v["crosstalk"] == pytest.approx(TRUE["crosstalk"], rel=0.1)
    for name in ("photon_scale", "pulse_fwhm_ps", "bin_width_ps", "start_offset_ps"):
        assert e[name] is not None and e[name] > 0
        assert abs(v[name] - TRUE.get(name, FLOOR)) < 5 * e[name]  # Fisher errors are honest here
    assert 0.8 < recovered.deviance < 1.3  # Poisson noise only: deviance per bin ~ 1
    assert [s["step"] for s in recovered.steps] == ["scale", "pulse", "noise", "joint"]
    assert all(s["deviance_after"] <= s["deviance_before"] + 1e-9 for s in recovered.steps)


def test_steps_stack_and_scale_alone_only_fits_the_scale(simulated):
    start = {"bin_width_ps": TRUE["bin_width_ps"], "start_offset_ps": TRUE["start_offset_ps"],
             "pulse_fwhm_ps": TRUE["pulse_fwhm_ps"], "crosstalk": TRUE["crosstalk"], "floor_counts": FLOOR}
    fit = fit_sensor_model(simulated, steps=["scale"], start=start)
    assert fit.fitted == ["photon_scale"]
    assert fit.values["bin_width_ps"] == TRUE["bin_width_ps"]
    assert fit.values["photon_scale"] == pytest.approx(TRUE["photon_scale"], rel=0.005)


def test_calibrated_sensor_round_trips_and_reproduces_the_data(recovered, simulated, tmp_path):
    base = _sensor(photon_scale=1.0, bin_width_ps=100.0)
    s = calibrated_sensor(base, recovered, lights_on=False)
    path = tmp_path / "cal.toml"
    s.save(path)
    loaded = load_sensor_file(path)
    assert loaded.bin_width_ps == pytest.approx(recovered.values["bin_width_ps"])
    assert loaded.dark_rate_hz * ITERS * loaded.bin_width_ps * 1e-12 == pytest.approx(recovered.values["floor_counts"])
    mu = np.asarray(expected_histogram(loaded, simulated.times_ps[5], simulated.weights[5], lights_on=False))
    truth = np.asarray(expected_histogram(_sensor(), simulated.times_ps[5], simulated.weights[5], lights_on=False))
    assert np.abs(mu - truth).sum() / truth.sum() < 0.02


def test_saturated_and_empty_zones_are_left_out_with_a_message(simulated):
    counts = simulated.counts.copy()
    counts[2, 0, 20] = 2**24 - 1
    counts[3, 0] = 5.0  # flat: no signal
    cs = CaptureSet(counts, simulated.times_ps, simulated.weights, ITERS, simulated.labels)
    used, messages = usable_zones(cs)
    assert not used[2, 0] and not used[3, 0] and used.sum() == len(DISTANCES) - 2
    assert f"capture {simulated.labels[2]} zone 0: saturated (a bin at 16777215), left out" in messages
    assert any("zone 0: no signal (net peak 0 counts < 100), left out" in m for m in messages)


def test_no_signal_anywhere_is_a_clear_error(simulated):
    cs = CaptureSet(np.full_like(simulated.counts, 3.0), simulated.times_ps, simulated.weights, ITERS, simulated.labels)
    with pytest.raises(UserError, match="no capture zone has usable signal: 12 left out"):
        fit_sensor_model(cs)


def test_bad_starts_are_rejected_or_detected(simulated):
    with pytest.raises(UserError, match=r"start value bin_width_ps=300 ps is outside its bounds \[50, 200\]"):
        fit_sensor_model(simulated, start={"bin_width_ps": 300.0})
    with pytest.raises(UserError, match="unknown calibration step\\(s\\) shift; allowed: scale, pulse, noise"):
        fit_sensor_model(simulated, steps=["shift"])
    # a time offset 25 bins off, fitting the scale alone: the peaks cannot match and the fit says so
    with pytest.raises(UserError, match="did not lock onto the measured peaks .* start is probably too far off"):
        fit_sensor_model(simulated, steps=["scale"], start={"start_offset_ps": 1000.0})


def _jittered_captures(offset_sd_ps, seed=1):
    """Like :func:`_captures`, but each capture's time base is off by a random offset the model does not know."""
    s = _sensor()
    rng = np.random.default_rng(seed)
    counts, times, weights = [], [], []
    for d in DISTANCES:
        t, w = wall_arrivals(WallScene(distance_m=float(d), albedo=1.0), s)
        t, w = t.reshape(9, -1)[[4]], w.reshape(9, -1)[[4]]
        mu = np.asarray(expected_histogram(s, t + rng.normal(0.0, offset_sd_ps), w, lights_on=False))
        counts.append(rng.poisson(mu))
        times.append(t)
        weights.append(w)
    return CaptureSet(np.array(counts, dtype=np.float64), np.array(times), np.array(weights), ITERS,
                      tuple(f"{d:.2f} m" for d in DISTANCES))


def test_bootstrap_agrees_with_fisher_when_the_model_is_right(simulated, recovered):
    from nlosplan.calibration import bootstrap_errors

    seen = []
    b = bootstrap_errors(simulated, recovered, resamples=10, seed=3, progress=lambda i, n: seen.append((i, n)))
    assert seen[-1] == (10, 10) and b.resamples == 10
    assert set(b.errors) == set(recovered.fitted)
    for name in ("photon_scale", "bin_width_ps", "start_offset_ps", "pulse_fwhm_ps"):
        ratio = b.errors[name] / recovered.errors[name]
        assert 0.3 < ratio < 3.0, (name, ratio)  # resampling 12 captures: the same size as the Fisher error
        lo, hi = b.intervals[name]
        assert lo < recovered.values[name] < hi
    assert b.to_dict()["intervals"]["bin_width_ps"][0] == b.intervals["bin_width_ps"][0]


@pytest.mark.slow  # ~20 s: a full fit and 10 refits
def test_bootstrap_sees_what_fisher_cannot_a_time_base_wandering_between_captures():
    from nlosplan.calibration import bootstrap_errors

    cs = _jittered_captures(offset_sd_ps=6.0)
    start = {"bin_width_ps": 94.0, "start_offset_ps": -1100.0, "pulse_fwhm_ps": 150.0}
    fit = fit_sensor_model(cs, start=start, noise="global")
    b = bootstrap_errors(cs, fit, resamples=10, seed=0)
    # photon counting alone pins the offset to well under a picosecond; the captures scatter by 6 ps, and the
    # offset (at t = 0) is extrapolated from returns at 0.5-2.7 ns: ~6 ps x 0.76 (regression intercept) ~ 4.5 ps
    assert fit.errors["start_offset_ps"] < 0.5
    assert b.errors["start_offset_ps"] > 4 * fit.errors["start_offset_ps"]
    assert 1.0 < b.errors["start_offset_ps"] < 20.0


def test_bootstrap_refuses_too_few_resamples_or_captures(simulated, recovered):
    from nlosplan.calibration import bootstrap_errors

    with pytest.raises(UserError, match="at least 5"):
        bootstrap_errors(simulated, recovered, resamples=3)
    one = fit_sensor_model(simulated.subset([5]), start={"bin_width_ps": 91.0, "start_offset_ps": -1150.0})
    with pytest.raises(UserError, match="at least 2 captures"):
        bootstrap_errors(simulated.subset([5]), one, resamples=5)
