"""The parameter uncertainty of a calibrated sensor (X.uncertainty.json beside X.toml): loader, validator, and the
worlds drawn from it."""

import json

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.sensor_models.presets import PRESET_NAMES, uncertainty
from nlosplan.sensor_models.uncertainty import load_uncertainty, uncertainty_for, uncertainty_path, validate_uncertainty

GOOD = {"sensor": "tmf8828-3x3-short",
        "parameters": {"photon_scale": {"value": 2.35, "std": 0.2, "lo": 1.8, "hi": 2.9},
                       "jitter_fwhm_ps": {"value": 60.0, "std": 25.0, "lo": 0.0, "hi": 150.0}},
        "samples": []}


def _write(tmp_path, data) -> str:
    sensor = tmp_path / "calibrated.toml"
    preset("tmf8828-3x3-short").save(sensor)
    uncertainty_path(sensor).write_text(json.dumps(data))
    return str(sensor)


def test_only_the_calibrated_denali_preset_ships_uncertainty_and_unknown_names_are_refused():
    assert [name for name in PRESET_NAMES if uncertainty(name) is not None] == ["denali-tmf8828-3x3"]
    data, where = uncertainty_for("denali-tmf8828-3x3")  # validated on the way
    assert where == "preset denali-tmf8828-3x3" and set(data["parameters"]) == {"photon_scale", "dark_rate_hz"}
    with pytest.raises(UserError, match="unknown sensor preset 'tmf9999'"):
        uncertainty("tmf9999")
    data, where = uncertainty_for("tmf8828-3x3-short")
    assert data is None and "ships no parameter uncertainty" in where


def test_a_hand_made_file_beside_the_sensor_is_found_and_validated(tmp_path):
    sensor = _write(tmp_path, GOOD)
    assert uncertainty_path(sensor).name == "calibrated.uncertainty.json"
    data, where = uncertainty_for(sensor)
    assert where.endswith("calibrated.uncertainty.json")
    assert data["parameters"]["photon_scale"] == {"value": 2.35, "std": 0.2, "lo": 1.8, "hi": 2.9}
    assert load_uncertainty(where) == data
    other = tmp_path / "bare.toml"
    preset("tmf8828-3x3-short").save(other)
    assert uncertainty_for(str(other))[0] is None


@pytest.mark.parametrize("change, words", [
    (lambda d: d["parameters"]["photon_scale"].update(std=-1), "parameters.photon_scale.std must be >= 0"),
    (lambda d: d["parameters"]["photon_scale"].update(lo=3.0), "parameters.photon_scale: needs lo <= value <= hi"),
    (lambda d: d["parameters"].update(speed={"value": 1, "std": 0, "lo": 0, "hi": 2}),
     "'speed' is not a numeric sensor parameter"),
    (lambda d: d["parameters"]["photon_scale"].pop("std"), "parameters.photon_scale must hold exactly value, std"),
    (lambda d: d["parameters"]["jitter_fwhm_ps"].update(hi="wide"), "parameters.jitter_fwhm_ps.hi must be a finite"),
    (lambda d: d["parameters"]["photon_scale"].update(lo=-1.0, value=-0.5), "parameters.photon_scale.lo"),
    (lambda d: d.update(samples=[{"photon_scale": 2.0, "albedo": 0.5}]), "samples[0].albedo is not among"),
    (lambda d: d.update(samples={"photon_scale": 2.0}), "samples must be a list"),
    (lambda d: d.pop("sensor"), "sensor must name the preset or file"),
    (lambda d: d.update(extra=1), "unknown key(s) extra"),
])
def test_a_bad_field_is_one_line_naming_it(tmp_path, change, words):
    data = json.loads(json.dumps(GOOD))
    change(data)
    with pytest.raises(UserError, match=None) as exc:
        validate_uncertainty(data, "cal.uncertainty.json")
    msg = str(exc.value)
    assert words in msg and msg.startswith("cal.uncertainty.json") and "\n" not in msg


def test_bad_file_is_refused_by_the_design_command_with_exit_2(tmp_path, capsys):
    from nlosplan.cli import main

    bad = json.loads(json.dumps(GOOD))
    bad["parameters"]["photon_scale"]["std"] = -1
    sensor = _write(tmp_path, bad)
    cfg = tmp_path / "d.toml"
    cfg.write_text(f'[space]\nreference = "{sensor}"\nzones = ["1x1"]\n')
    assert main(["design", "--quick", "--config", str(cfg), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "photon_scale.std must be >= 0" in err[0]


def test_worlds_draw_from_the_samples_or_from_clipped_normals():
    from nlosplan.planner.design.worlds import WorldRange, WorldsConfig, draw_worlds

    ref = preset("tmf8828-3x3-short")
    cfg = WorldsConfig(count=40, ranges=(WorldRange("albedo", 0.3, 0.7),
                                         WorldRange("photon_scale", 0.5, 2.0, relative=True)))
    normal = draw_worlds(cfg, ref, "off", 0, validate_uncertainty(GOOD))
    ps = np.array([w.sensor["photon_scale"] for w in normal[1:]])
    jit = np.array([w.sensor["jitter_fwhm_ps"] for w in normal[1:]])
    assert ps.min() >= 1.8 and ps.max() <= 2.9 and abs(ps.mean() - 2.35) < 0.15  # the calibration replaces the range
    assert jit.min() >= 0.0 and jit.max() <= 150.0 and (jit == 0.0).any() is not None
    assert all("albedo" in w.scene for w in normal[1:])  # the declared ranges still apply to the rest
    samples = {**GOOD, "samples": [{"photon_scale": 2.0, "jitter_fwhm_ps": 10.0},
                                   {"photon_scale": 2.5, "jitter_fwhm_ps": 90.0}]}
    drawn = draw_worlds(cfg, ref, "off", 0, validate_uncertainty(samples))
    pairs = {(w.sensor["photon_scale"], w.sensor["jitter_fwhm_ps"]) for w in drawn[1:]}
    assert pairs <= {(2.0, 10.0), (2.5, 90.0)} and len(pairs) == 2  # whole samples, joint values kept
