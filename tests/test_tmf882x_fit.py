"""Tests of the TMF882x time-base and pulse-shape fit (synthetic and real data)."""

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from nlosplan.constants import C_M_PER_PS
from nlosplan.errors import UserError
from nlosplan.sensor_models.pipeline import bin_arrivals
from nlosplan.calibration.tmf882x_fit import (
    DistanceCaptures,
    fit_pulse_shape,
    fit_timebase,
    holdout_report,
    load_distance_captures,
    predict_histogram,
)

REAL = Path(__file__).resolve().parents[1].parent / "shared/data/tmf882x_distance/distance_data_even.json"

BW_TRUE = 91.0
OFFSET_TRUE = -13.0 * BW_TRUE
# Sharp 2-bin core and an exponential tail. The big rise (sample 1) starts 0.1 bin
# after the nominal arrival, so the half-max leading edge is at the nominal arrival
# to well within a bin, as the module's convention assumes.
PULSE_TRUE = np.concatenate([[0.04, 0.36, 0.30, 0.14], 0.06 * 0.7 ** np.arange(20)])
PULSE_TRUE = PULSE_TRUE / PULSE_TRUE.sum()
T0_TRUE = -0.9 * BW_TRUE


def _synthetic(seed=1234, noise=True):
    d = np.round(np.arange(0.06, 0.4001, 0.005), 6)
    edges = OFFSET_TRUE + BW_TRUE * np.arange(129)
    pulse = (T0_TRUE + BW_TRUE * np.arange(PULSE_TRUE.size), BW_TRUE, PULSE_TRUE)
    amp = 3e5 * (0.2 / d) ** 2
    mean = np.asarray(bin_arrivals((2 * d / C_M_PER_PS)[:, None], amp[:, None], edges, 0.0, pulse))
    mean = mean + (20.0 + 400.0 * d)[:, None]
    h = np.random.default_rng(seed).poisson(mean).astype(float) if noise else mean
    hists = np.zeros((d.size, 9, 128))
    hists[:, 4] = h
    return DistanceCaptures(d, hists, np.zeros((d.size, 128))), mean


@pytest.fixture(scope="module")
def synthetic():
    return _synthetic()


def test_synthetic_timebase_recovered(synthetic):
    captures, _ = synthetic
    tb = fit_timebase(captures)
    assert tb.n_used == captures.distance_m.size
    assert abs(tb.bin_width_ps - BW_TRUE) / BW_TRUE < 0.01
    assert abs(tb.start_offset_ps - OFFSET_TRUE) / BW_TRUE < 0.3
    assert tb.start_offset_ps == pytest.approx(-tb.zero_bin * tb.bin_width_ps)
    assert 0 < tb.bin_width_se_ps < 1.0
    assert tb.residual_rms_bins < 0.2


def test_synthetic_pulse_reproduces_histograms(synthetic):
    captures, mean = synthetic
    tb = fit_timebase(captures)
    p = fit_pulse_shape(captures, tb, n_samples=24)
    s = np.asarray(p.samples)
    assert s.shape == (24,) and np.all(s >= 0) and s.sum() == pytest.approx(1.0)
    assert p.step_ps == tb.bin_width_ps
    assert -3 * p.step_ps <= p.t0_ps <= -2 * p.step_ps
    # the (start_offset, t0, samples) triple reproduces the noise-free histograms
    for i in range(0, captures.distance_m.size, 7):
        pred, _, _ = predict_histogram(captures.distance_m[i], mean[i], tb, p)
        assert np.sum(np.abs(pred - mean[i])) / np.sum(mean[i] - mean[i].min()) < 0.05
        assert np.argmax(pred) == np.argmax(mean[i])
    assert 100.0 < p.core_fwhm_ps < 300.0
    # shape and combined offset recovered: fitted samples = true samples moved by k samples
    k = int(np.argmax(s > 0.5 * PULSE_TRUE[0])) if s[0] < 0.5 * PULSE_TRUE[0] else 0
    np.testing.assert_allclose(s[k : k + 6], PULSE_TRUE[:6], atol=0.01)
    fitted = (p.t0_ps + k * p.step_ps - tb.start_offset_ps) / tb.bin_width_ps
    assert fitted == pytest.approx((T0_TRUE - OFFSET_TRUE) / BW_TRUE, abs=0.1)


@pytest.fixture(scope="module")
def real():
    if not REAL.is_file():
        pytest.skip(f"real TMF882x data not found at {REAL}")
    return load_distance_captures(REAL)


def test_real_file_loads(real):
    n = real.distance_m.size
    assert real.hists.shape == (n, 9, 128) and real.reference.shape == (n, 128)
    assert real.hists.dtype == np.float64


def test_real_timebase(real):
    tb = fit_timebase(real)
    assert 80.0 < tb.bin_width_ps < 100.0
    assert tb.residual_rms_bins < 0.5
    assert tb.n_used >= 60
    assert 11.0 < tb.zero_bin < 14.0


def test_real_holdout(real):
    report = holdout_report(real, fit_fraction=0.5, seed=0)
    assert report.peak_bin_error_mean_abs < 1.0
    assert report.n_fit + report.n_holdout >= 60 and report.n_holdout >= 30
    assert report.l1_mean < 0.15
    assert 80.0 < report.bin_width_ps < 100.0
    json.dumps(dataclasses.asdict(report))  # JSON-ready
    again = holdout_report(real, fit_fraction=0.5, seed=0)
    assert again == report  # deterministic


@pytest.mark.parametrize(
    "content",
    [None, "{not json", "[]", '[{"dist_to_plane": 0.1}]', '[{"dist_to_plane": 0.1, "hists": [[1, 2]], "reference_hist": [1]}]'],
    ids=["missing", "not-json", "empty", "missing-key", "bad-shape"],
)
def test_bad_file_raises_user_error(tmp_path, content):
    path = tmp_path / "captures.json"
    if content is not None:
        path.write_text(content)
    with pytest.raises(UserError) as info:
        load_distance_captures(path)
    msg = str(info.value)
    assert str(path) in msg and "\n" not in msg
