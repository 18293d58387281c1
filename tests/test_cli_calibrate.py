"""``nlosplan calibrate`` on the real TMF882x plane captures: held-out errors, sensor file, one-line errors."""

import json

import pytest

from nlosplan.cli import main
from nlosplan.sensor_models import SensorConfig


@pytest.fixture(scope="module")
def real(shared_data_module, tmp_path_factory):
    folder = tmp_path_factory.mktemp("calibrate")
    data = shared_data_module / "tmf882x_distance" / "distance_data_even.json"
    return data, folder


@pytest.fixture(scope="module")
def shared_data_module():
    from pathlib import Path

    path = Path(__file__).resolve().parents[1].parent / "shared" / "data"
    if not path.is_dir():
        pytest.skip(f"shared data not found at {path}")
    return path


def test_calibrate_real_data_with_holdout(real, capsys):
    data, folder = real
    out = folder / "cal.toml"
    code = main(["calibrate", str(data), "--holdout", "0.5", "--seed", "0", "--out", str(out),
                 "--plot", str(folder / "cal.png"), "--json"])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    h = result["holdout"]
    assert h["n_fit"] == 34 and h["n_holdout"] == 35
    assert h["peak_bin_error_mean_abs"] < 0.2 and h["peak_bin_error_max_abs"] <= 1
    assert h["shape_l1_mean"] < 0.10
    v = result["fit"]["values"]
    assert 91.0 < v["bin_width_ps"] < 94.0  # SENSOR_FACTS: ~91-93 ps measured on this data
    assert all(result["fit"]["errors"][k] is not None for k in ("bin_width_ps", "start_offset_ps", "photon_scale"))
    s = SensorConfig.load(out)
    assert s.name == "tmf8828-3x3-short-calibrated" and s.bin_width_ps == pytest.approx(v["bin_width_ps"])
    assert (folder / "cal.png").stat().st_size > 10_000


@pytest.mark.parametrize("argv, message", [
    (["--zones", "9"], "--zones '9' must be flat zone indices 0..8"),
    (["--steps", "scale,shift"], "unknown calibration step(s) shift; allowed: scale, pulse, noise"),
    (["--start", "bin_width_ps=500"], "start value bin_width_ps=500 ps is outside its bounds [50, 200]"),
    (["--holdout", "1.5"], "--holdout 1.5 must be >= 0 and < 1"),
    (["--sensor", "tmf8828-8x8-short"], "the captures have 9 zones but sensor tmf8828-8x8-short has 64"),
])
def test_bad_input_exits_2_with_one_line(real, capsys, argv, message):
    data, folder = real
    code = main(["calibrate", str(data), "--out", "", "--plot", "", *argv])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert message in err and len(err.splitlines()) == 1


def test_missing_file_is_one_line(tmp_path, capsys):
    assert main(["calibrate", str(tmp_path / "none.json"), "--out", "", "--plot", ""]) == 2
    assert "cannot read capture file" in capsys.readouterr().err
