"""The floor's noise statistics (issue 35: is the real floor Poisson?): the estimator, then the real captures."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest

from nlosplan.calibration.floor_noise import fano_factors, floor_dispersion, floor_windows
from nlosplan.cli import main
from nlosplan.errors import UserError

PLANE = Path(__file__).resolve().parents[2] / "shared" / "data" / "tmf882x_distance" / "distance_data_even.json"


def _with_tail(rng, n=60, level=150.0):
    """Captures whose late bins hold a floor plus a decaying tail (the trend the estimator removes)."""
    t = np.arange(128)
    mean = level + 400.0 * np.exp(-(t - 40.0).clip(0) / 20.0) * (t >= 40)
    return np.broadcast_to(mean, (n, 9, 128)), rng


def test_poisson_counts_about_a_trend_give_one():
    mean, rng = _with_tail(np.random.default_rng(1))
    d = floor_dispersion(rng.poisson(mean).astype(float))
    assert d.real_interval[0] < 1.0 < d.real_interval[1] + 0.02
    assert abs(d.real_median - d.model_median) < 0.05
    assert d.windows == 60 * 9 and (d.first_bin, d.last_bin) == (96, 127)


def test_a_pedestal_and_excess_noise_are_told_apart_from_poisson():
    mean, rng = _with_tail(np.random.default_rng(2))
    pedestal = 100.0 + rng.poisson(mean - 100.0)       # 100 counts of the floor do not scatter: Fano ~ 1/3
    d = floor_dispersion(pedestal.astype(float))
    assert d.real_median < 0.5 and d.real_interval[1] < d.model_interval[0]
    gain = rng.poisson(mean * rng.gamma(25.0, 1 / 25.0, size=mean.shape))   # 20 % gain noise per bin
    d = floor_dispersion(gain.astype(float))
    assert d.real_median > 3.0 and d.real_interval[0] > d.model_interval[1]


def test_the_trend_is_removed_not_counted_as_noise():
    t = np.arange(32)
    slope = np.tile(200.0 + 10.0 * t, (5, 1))            # a noiseless straight tail: no residual at degree >= 1
    assert np.allclose(fano_factors(slope, degree=1), 0.0, atol=1e-9)
    assert fano_factors(slope, degree=0).min() > 5.0      # a constant floor would call the slope noise


def test_empty_and_malformed_histograms_are_refused_in_one_line():
    with pytest.raises(UserError, match="no capture has a floor of 20 counts"):
        floor_windows(np.zeros((3, 9, 128)))
    with pytest.raises(UserError, match="captures x zones x bins"):
        floor_windows(np.ones((9, 128)))
    with pytest.raises(UserError, match="at least 8 bins"):
        floor_windows(np.ones((3, 9, 100)), first_bin=96)


@pytest.mark.skipif(not PLANE.exists(), reason="../shared/data (the real plane captures) is not next to the project")
def test_the_real_tmf882x_floor_is_poisson(capsys):
    """Real captures: the floor's Fano factor is that of Poisson counts (0.96, the model's draws 0.98)."""
    assert main(["bench", "real", "--parts", "floor", "--plane", str(PLANE), "--json"]) == 0
    f = json.loads(capsys.readouterr().out)["floor"]
    assert f["poisson"] is True
    assert 0.9 < f["real_median"] < 1.05 and 0.9 < f["model_median"] < 1.05
    assert 100 < f["level_counts"] < 250 and f["windows"] > 600
    assert len(f["per_zone"]) == 9


def test_bench_real_floor_text_and_missing_file(capsys, tmp_path):
    if PLANE.exists():
        assert main(["bench", "real", "--parts", "floor", "--plane", str(PLANE)]) == 0
        out = capsys.readouterr().out
        assert "Fano factor (residual variance / mean): real 0.9" in out and "scatters like Poisson" in out
    assert main(["bench", "real", "--parts", "floor", "--plane", str(tmp_path / "none.json")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "plane captures not found" in err[0]
