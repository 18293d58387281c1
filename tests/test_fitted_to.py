"""The ``fitted_to`` record: which real data a preset's (or a calibrated sensor file's) values were fitted to."""

import hashlib
import json
import re

import pytest

from nlosplan.calibration.stats_file import load_stats, shipped_path
from nlosplan.calibration.stats_workflow import stats_record
from nlosplan.cli import main
from nlosplan.errors import UserError
from nlosplan.sensor_models import PRESET_NAMES, load_sensor_file, preset
from nlosplan.sensor_models import fitted_to as ft
from nlosplan.sensor_models import preset_sources as ps
from nlosplan.sensor_models.presets_denali import DENALI_NUISANCES_FIT, DENALI_SCENE_FIT


def run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_denali_preset_record_names_table2_its_levels_and_their_parameters():
    s = preset("denali-tmf8828-3x3")
    rec = ps.preset_record("denali-tmf8828-3x3")
    t2, levels = rec[0], rec[1]
    assert t2.source == "DENALI Table 2" and t2.use == "fitted" and "calibration/data/denali_table2.toml" in t2.ref
    # the hash the record names is the shipped file's (unchanged since the fit; a new Table 2 needs a refit)
    assert t2.sha256 == hashlib.sha256(shipped_path().read_bytes()).hexdigest() == ps.TABLE2_SHA256
    assert t2.parameters == {"photon_scale": s.photon_scale, "dark_rate_hz": s.dark_rate_hz}
    assert t2.scene["albedo"] == DENALI_SCENE_FIT["albedo"] == 0.3667
    assert t2.scene["early_residual_counts"] == DENALI_NUISANCES_FIT["early_residual_counts"]
    assert t2.held["ambient_rate_hz"] == 0.0 and t2.held["diffuse_albedo"] == 0.2  # held, not fitted
    assert "calibrate --stats denali-table2" in t2.by
    assert levels.source == "DENALI checkpoint levels" and "5020" in levels.what and "7.43" in levels.what
    assert levels.parameters == t2.parameters and levels.sha256 == t2.sha256
    # the time base and pulse were measured on another unit: assumed, not fitted to DENALI's
    others = rec[2:]
    assert {o.use for o in others} == {"assumed"}
    assert {k for o in others for k in o.parameters} == {"bin_width_ps", "start_offset_ps", "pulse_shape",
                                                         "pulse_shape_step_ps", "pulse_shape_t0_ps",
                                                         "pulse_tail_fraction", "pulse_tail_decay_ps"}
    assert ft.record_summary(rec) == "DENALI Table 2 + checkpoint levels"
    # the 8x8 preset takes the 3x3 fit's values: the same sources, assumed, with the 8x8 nuisances
    rec8 = ps.preset_record("denali-tmf8828-8x8")
    assert [r.source for r in rec8] == [r.source for r in rec] and {r.use for r in rec8} == {"assumed"}
    assert rec8[0].scene["early_residual_counts"] == pytest.approx(48.76 * 10_240 / 10_240_000)
    assert ft.record_summary(rec8) == "none (assumed)"


@pytest.mark.parametrize("name", PRESET_NAMES)
def test_every_preset_record_holds_its_own_values_and_round_trips(name):
    s = preset(name)
    rec = ps.preset_record(name)
    assert rec, name  # every shipped preset takes some values from real data (none is datasheet-only)
    for src in rec:
        assert src.parameters and src.use in ft.USES and src.ref and src.what
        for k, v in src.parameters.items():
            assert ft.same_value(v, getattr(s, k)), (name, k)
    kept, changed = ft.current_record(s, rec)
    assert kept == rec and changed == []
    assert ft.parse_record(json.loads(json.dumps(ft.record_dicts(rec)))) == rec


def test_which_presets_are_fitted_and_which_assumed():
    fitted = {n for n in PRESET_NAMES if any(s.use == "fitted" for s in ps.preset_record(n))}
    assert fitted == {"tmf8828-3x3-short", "tmf8828-3x3-plane-unit", "denali-tmf8828-3x3"}
    vl = ps.preset_record("vl53l8ch-8x8")
    assert [set(s.parameters) for s in vl] == [{"photon_scale", "ambient_rate_hz", "dark_rate_hz"}]
    assert "no VL53L8CH data" in vl[0].what
    unit = ps.preset_record("tmf8828-3x3-plane-unit")[0]
    assert {"zone_gains", "iterations", "time_walk_ps"} <= set(unit.parameters)


def test_plane_captures_hash_is_the_shared_files(shared_data):
    path = shared_data / "tmf882x_distance" / "distance_data_even.json"
    assert hashlib.sha256(path.read_bytes()).hexdigest() == ps.PLANE_SHA256


def test_sensor_show_prints_fitted_to(capsys):
    code, out, _ = run(capsys, "sensor", "show", "denali-tmf8828-3x3")
    assert code == 0
    section = out[out.index("fitted to:"):]
    assert "DENALI Table 2: nlosplan/calibration/data/denali_table2.toml" in section
    assert f"sha256 {ps.TABLE2_SHA256[:16]}" in section
    assert "gave: photon_scale = 0.28395, dark_rate_hz = 1.24506e+06" in section
    assert "held fixed: ambient_rate_hz = 0" in section
    assert section.index("DENALI checkpoint levels") < section.index("assumed from real data of another unit")
    code, out, _ = run(capsys, "sensor", "show", "vl53l8ch-8x8")
    assert "fitted to no real data of this sensor" in out
    code, out, _ = run(capsys, "sensor", "list", "--json")
    got = {r["name"]: r["fitted_to"] for r in json.loads(out)["presets"]}
    assert got["denali-tmf8828-3x3"] == "DENALI Table 2 + checkpoint levels"
    assert got["tmf8828-3x3-short"] == "TMF882x plane captures" and got["tmf8828-4x4-short"] == "none (assumed)"


def test_hand_written_files_datasheet_values_and_no_record(capsys, tmp_path):
    s = preset("tmf8828-3x3-short")
    full = tmp_path / "full.toml"  # every field, no base: nothing is known about where the values come from
    full.write_text(s.to_toml())
    code, out, _ = run(capsys, "sensor", "show", str(full))
    assert code == 0 and "fitted to: not recorded: no record (the file has neither 'base' nor 'fitted_to')" in out
    sheet = tmp_path / "sheet.json"  # a file that says its values are from datasheets: an empty record
    sheet.write_text(s.to_json(fitted_to=[]))
    code, out, _ = run(capsys, "sensor", "show", str(sheet))
    assert code == 0 and "fitted to no real data (datasheet values)" in out
    assert load_sensor_file(sheet) == s  # loads as before


@pytest.mark.parametrize("fmt", ["toml", "json"])
def test_record_round_trips_through_a_sensor_file_and_drops_changed_values(capsys, tmp_path, fmt):
    code, text, _ = run(capsys, "sensor", "show", "denali-tmf8828-3x3", f"--{fmt}")
    path = tmp_path / f"d.{fmt}"
    path.write_text(text)
    s, rec, changed, origin = ps.sensor_record(path)
    assert s == preset("denali-tmf8828-3x3") and rec == ps.preset_record("denali-tmf8828-3x3") and not changed
    assert origin == "the file's own record"
    # a value changed in the file (not in its record) is no longer fitted to Table 2 and is named
    if fmt == "json":
        data = json.loads(text)
        data["photon_scale"] = 0.3
        path.write_text(json.dumps(data))
    else:
        path.write_text(re.sub(r"(?m)^photon_scale = .*$", "photon_scale = 0.3", text, count=1))
    s, rec, changed, _ = ps.sensor_record(path)
    assert s.photon_scale == 0.3 and changed == ["photon_scale"]
    assert rec[0].parameters == {"dark_rate_hz": s.dark_rate_hz}
    code, out, _ = run(capsys, "sensor", "show", str(path))
    assert "changed since the record (no longer fitted to it): photon_scale" in out
    # shown again as a file, the record holds only what still holds
    code, text2, _ = run(capsys, "sensor", "show", str(path), "--json")
    assert [list(e["parameters"]) for e in json.loads(text2)["fitted_to"]][:2] == [["dark_rate_hz"]] * 2


def test_a_base_file_without_a_record_takes_its_presets_less_what_it_changes(tmp_path):
    path = tmp_path / "b.toml"
    path.write_text('base = "tmf8828-3x3-short"\nbin_width_ps = 95.0\n')
    s, rec, changed, origin = ps.sensor_record(path)
    assert changed == ["bin_width_ps"] and "base preset tmf8828-3x3-short" in origin
    assert "bin_width_ps" not in rec[0].parameters and rec[0].parameters["start_offset_ps"] == s.start_offset_ps
    path.write_text('base = "tmf8828-3x3-short"\nbin_width_ps = 95.0\nphoton_scale = 1.0\nambient_rate_hz = 0.0\n'
                    'dark_rate_hz = 0.0\n')
    _, rec, changed, _ = ps.sensor_record(path)
    assert [r.source for r in rec] == ["TMF882x plane captures: time base and pulse"]
    assert changed == ["bin_width_ps", "photon_scale", "ambient_rate_hz", "dark_rate_hz"]


@pytest.mark.parametrize("entry, message", [
    ({"source": "x", "what": "y", "ref": "z", "use": "guessed", "parameters": {}},
     "fitted_to[0].use is 'guessed'; allowed: fitted, assumed"),
    ({"source": "x", "what": "y", "ref": "z", "use": "fitted", "parameters": {"colour": 1.0}},
     "fitted_to[0].parameters: 'colour' is not a sensor field"),
    ({"source": "x", "what": "y", "use": "fitted", "parameters": {}}, "fitted_to[0]: missing key ref"),
    ({"source": "x", "what": "y", "ref": "z", "use": "fitted", "parameters": {}, "sha256": "abc"},
     "fitted_to[0].sha256 must be 64 lower-case hex digits"),
    ({"source": "x", "what": "y", "ref": "z", "use": "fitted", "parameters": {"photon_scale": "big"}},
     "fitted_to[0].parameters.photon_scale must be a number"),
])
def test_bad_record_in_a_sensor_file_is_one_line_exit_2(capsys, tmp_path, entry, message):
    path = tmp_path / "bad.json"
    path.write_text(json.dumps({"base": "tmf8828-3x3-short", "fitted_to": [entry]}))
    code, out, err = run(capsys, "sensor", "show", str(path))
    assert code == 2 and message in err and len(err.strip().splitlines()) == 1 and out == ""
    with pytest.raises(UserError, match=re.escape(message)):
        load_sensor_file(path)


def test_stats_record_names_the_file_its_hash_levels_and_keeps_the_rest(tmp_path):
    stats = tmp_path / "t2.toml"
    stats.write_bytes(shipped_path().read_bytes() + b"\n# a copy\n")
    table = load_stats(stats)
    start = preset("denali-tmf8828-3x3")
    fitted = start.replace(photon_scale=0.3, dark_rate_hz=1.3e6)
    values = {"photon_scale": 0.3, "dark_rate_hz": 1.3e6, "ambient_rate_hz": 0.0,
              **{k: v for k, v in DENALI_SCENE_FIT.items() if k != "mount"}, **DENALI_NUISANCES_FIT, "albedo": 0.4}
    free = ("photon_scale", "dark_rate_hz", "albedo")
    rec = stats_record(stats, table, "denali-tmf8828-3x3", fitted, values, free, "3x3", "the command", True)
    first, levels = rec[0], rec[1]
    assert first.ref == str(stats) and first.sha256 == hashlib.sha256(stats.read_bytes()).hexdigest()
    assert first.sha256 != ps.TABLE2_SHA256  # the file it was given, not the shipped one
    assert first.source.startswith("DENALI (CVPR 2026), Table 2") and first.use == "fitted"
    assert first.parameters == {"photon_scale": 0.3, "dark_rate_hz": 1.3e6} and first.scene == {"albedo": 0.4}
    assert first.held["ambient_rate_hz"] == 0.0 and first.held["mount"] is True
    assert first.held["early_residual_counts"] == DENALI_NUISANCES_FIT["early_residual_counts"]
    assert "checkpoint mean count per bin = 5020 (mean_count)" in levels.what and levels.parameters == first.parameters
    # the start's Table-2 entries were refitted away; its time base and pulse tail stay, assumed as before
    assert [r.source for r in rec[2:]] == ["TMF882x plane captures: time base and pulse",
                                           "TMF882x plane captures: pulse tail"]
    kept, changed = ft.current_record(fitted, rec)
    assert kept == rec and not changed
    # the shipped file by its name: the package path and the recorded hash
    rec = stats_record("denali-table2", load_stats("denali-table2"), "denali-tmf8828-3x3", fitted, values, free,
                       "3x3", "the command", True)
    assert rec[0].sha256 == ps.TABLE2_SHA256 and "nlosplan/calibration/data/denali_table2.toml" in rec[0].ref
