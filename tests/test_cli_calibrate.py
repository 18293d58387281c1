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
                 "--plot", str(folder / "cal.png"), "--bootstrap", "5", "--json"])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    # refits on resampled real captures spread far more than photon counting allows: the model is not exact
    boot, fisher = result["bootstrap"], result["fit"]["errors"]
    assert boot["resamples"] == 5 and set(boot["errors"]) == set(result["fit"]["fitted"])
    for name in ("bin_width_ps", "start_offset_ps", "photon_scale"):
        assert boot["errors"][name] > 5 * fisher[name], name
    assert boot["errors"]["bin_width_ps"] < 2.0 and boot["errors"]["start_offset_ps"] < 50.0
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
    (["--bootstrap", "3"], "bootstrap resamples 3 < 5: give at least 5"),
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


def test_help_teaches_the_three_inputs(capsys):
    with pytest.raises(SystemExit) as exc:
        main(["calibrate", "--help"])
    assert exc.value.code == 0
    out = " ".join(capsys.readouterr().out.split())
    for text in ("a JSON file", "a DENALI folder", "a capture store",
                 "<lighton|lightoff>_NLOSdata/spad_histogram/NNN.npy",
                 "nlosplan calibrate ../shared/data/tmf882x_distance/distance_data_even.json",
                 "nlosplan calibrate denali-data/data --where zones=3x3,lights=off",
                 "nlosplan calibrate out/denali.sqlite --where"):
        assert text in out, text


@pytest.mark.parametrize("argv, message", [
    (["--where", "lights=off"], "--where applies to a DENALI folder or a capture store, not to JSON plane captures"),
    (["--fidelity", "draft"], "--fidelity applies to a DENALI folder or a capture store"),
])
def test_denali_only_flags_on_json_are_one_line(real, capsys, argv, message):
    data, _ = real
    assert main(["calibrate", str(data), "--out", "", "--plot", "", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and len(err.splitlines()) == 1


def test_a_file_that_is_neither_json_nor_a_store_is_one_line(tmp_path, capsys):
    folder = tmp_path / "A_8inch_3x3_lightoff_NLOSdata"
    (folder / "spad_histogram").mkdir(parents=True)
    assert main(["calibrate", str(folder), "--out", "", "--plot", ""]) == 2
    err = capsys.readouterr().err.strip()
    assert "is not a DENALI-layout folder" in err and "give the folder that holds" in err
    assert len(err.splitlines()) == 1
