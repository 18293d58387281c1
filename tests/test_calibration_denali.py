"""Calibration on DENALI-layout captures: known parameters recovered, the CLI on a folder and a store, one-line errors,
and the arrivals of the matching scenes reproduce the fast simulator."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from nlosplan.cli import main
from nlosplan.sensor_models import preset, resolve_sensor
from nlosplan.calibration import (
    CaptureSet,
    denali_capture_set,
    load_denali_captures,
    make_model,
    scene_arrivals,
)
from nlosplan.calibration.denali import quiet_floors, split_positions
from nlosplan.calibration.denali_data import matching_scene, wall_zones
from nlosplan.simulators import FastSimulator

ITERS = 550_000
DARK, AMBIENT = 40.0, 120.0  # counts per bin: lights-off floor, lights-on extra
TRUE = {"photon_scale": 2.0, "pulse_fwhm_ps": 300.0, "bin_width_ps": 91.0, "start_offset_ps": -1150.0,
        "crosstalk": 2e-4}
#: DENALI folder -> gantry positions captured (2 repeats each); A's positions sample the gantry's range
FOLDERS = {"A_8inch_3x3_lightoff_NLOSdata": (0, 19, 33, 47, 52, 68, 81, 99),
           "NOOBJECT_8inch_3x3_lighton_NLOSdata": (5, 60)}
REPEATS = 2


def _rate(counts_per_bin: float) -> float:
    return counts_per_bin / (ITERS * TRUE["bin_width_ps"] * 1e-12)


def _true_sensor():
    """The sensor that made the captures: a Gaussian pulse (no measured shape), every fitted field chosen."""
    return preset("tmf8828-3x3-short").replace(
        name="truth", pulse_shape=None, pulse_fwhm_ps=TRUE["pulse_fwhm_ps"], bin_width_ps=TRUE["bin_width_ps"],
        start_offset_ps=TRUE["start_offset_ps"], photon_scale=TRUE["photon_scale"], crosstalk=TRUE["crosstalk"],
        dark_rate_hz=_rate(DARK), ambient_rate_hz=_rate(AMBIENT), iterations=ITERS, saturation=False)


def _base_sensor():
    """The sensor to calibrate: the 3x3 preset's time base (2 % and 33 ps off) with a Gaussian pulse."""
    return preset("tmf8828-3x3-short").replace(name="gauss-3x3", pulse_shape=None, pulse_fwhm_ps=0.0)


def _write_folder(root, seed=0):
    """Poisson captures of the fast simulator's expected counts (independent of the fit's model), DENALI layout.

    Its time grid has the fit model's 8 nodes per bin: the linear split of arrivals onto nodes widens a
    pulse by ``(bin / nodes)**2 / 6`` in variance, which the default 4 nodes would add to the true width.
    """
    truth = _true_sensor()
    rng = np.random.default_rng(seed)
    for folder, positions in FOLDERS.items():
        obj, size, _, lights = folder.split("_")[:4]
        scenes = [matching_scene(obj, size.replace("inch", "in"), p, lights.removeprefix("light")) for p in positions]
        mean = FastSimulator(scenes, truth, fidelity={"time_oversample": 8}).expected()  # (P, 3, 3, 128)
        d = root / folder / "spad_histogram"
        d.mkdir(parents=True)
        for p, m in zip(positions, mean):
            np.save(d / f"{p:03d}.npy", rng.poisson(np.broadcast_to(m, (REPEATS,) + m.shape)).astype(np.int64))
    return root


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    return _write_folder(tmp_path_factory.mktemp("denali") / "data")


@pytest.fixture(scope="module")
def captures(folder):
    return load_denali_captures(folder)


@pytest.fixture(scope="module")
def capture_set(captures):
    return denali_capture_set(captures, _base_sensor())


@pytest.fixture(scope="module")
def cli_run(folder, tmp_path_factory):
    """``nlosplan calibrate FOLDER`` with a quarter of the gantry positions held out (one fit, shared by the tests)."""
    import contextlib
    import io

    out = tmp_path_factory.mktemp("cli")
    base = out / "gauss.toml"
    _base_sensor().save(base)
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        code = main(["calibrate", str(folder), "--sensor", str(base), "--holdout", "0.25", "--seed", "1",
                     "--out", str(out / "cal.toml"), "--plot", str(out / "cal.png"), "--json"])
    assert code == 0
    return json.loads(buf.getvalue()), out


def test_folder_is_read_with_its_labels(captures):
    n = sum(len(p) for p in FOLDERS.values()) * REPEATS
    assert len(captures) == n and captures.counts.shape == (n, 9, 128) and captures.zones == "3x3"
    lab = captures.labels
    assert sorted(lab["object"].unique()) == ["A", "NOOBJECT"]
    assert set(lab.loc[lab["object"] == "A", "lights"]) == {"off"}
    assert set(lab.loc[lab["object"] == "NOOBJECT", "lights"]) == {"on"}
    assert sorted(lab["position"].unique()) == sorted(set(sum(FOLDERS.values(), ())))
    assert captures.sensor.name == "denali-tmf8828-3x3"  # the importer's preset for 3x3 folders: DENALI's unit
    assert captures.capture_labels()[0] == "A_8in p00 off r0"
    # the counts are the files' (position 19, repeat 1 of A)
    row = int(np.flatnonzero((lab["object"] == "A") & (lab["position"] == 19) & (lab["repeat"] == 1))[0])
    raw = np.load(Path(captures.origin) / "A_8inch_3x3_lightoff_NLOSdata" / "spad_histogram" / "019.npy")
    np.testing.assert_array_equal(captures.counts[row], raw[1].reshape(9, 128))


def test_recovers_known_parameters(cli_run):
    fit = cli_run[0]["fit"]
    v, e = fit["values"], fit["errors"]
    assert set(fit["fitted"]) == {"photon_scale", "pulse_fwhm_ps", "bin_width_ps", "start_offset_ps", "crosstalk"}
    for name, truth in TRUE.items():
        assert e[name] is not None and e[name] > 0
        assert abs(v[name] - truth) < 4 * e[name], (name, v[name], truth, e[name])
    assert v["photon_scale"] == pytest.approx(TRUE["photon_scale"], rel=0.002)
    assert v["pulse_fwhm_ps"] == pytest.approx(TRUE["pulse_fwhm_ps"], rel=0.01)
    assert v["bin_width_ps"] == pytest.approx(TRUE["bin_width_ps"], abs=0.1)
    assert v["start_offset_ps"] == pytest.approx(TRUE["start_offset_ps"], abs=5.0)
    assert v["crosstalk"] == pytest.approx(TRUE["crosstalk"], rel=0.05)
    assert 0.9 < fit["deviance"] < 1.15  # Poisson noise only
    assert fit["messages"] == []


def test_quiet_floors_are_the_true_floors_despite_the_objects_late_return(capture_set, captures):
    lights = captures.labels["lights"].to_numpy()
    values = {**TRUE, "floor_counts": 0.0}
    floors = quiet_floors(capture_set, values, groups=captures.floor_groups())
    assert sorted(set(captures.floor_groups())) == ["A_8in off", "NOOBJECT_8in on"]
    assert floors[lights == "off"] == pytest.approx(DARK, rel=0.03)  # one floor per folder and zone
    assert floors[lights == "on"] == pytest.approx(DARK + AMBIENT, rel=0.02)
    alone = quiet_floors(capture_set, values)  # each capture alone: noisier, as unbiased
    assert np.mean(alone[lights == "off"]) == pytest.approx(DARK, rel=0.01)
    assert np.std(alone[lights == "off"]) > np.std(floors[lights == "off"])
    # the plane path's median of the last 30 bins sees A's three-bounce return at the near positions
    late = np.median(capture_set.counts[..., -30:], axis=-1)
    assert np.max(late[lights == "off"] - floors[lights == "off"]) > 3.0


def test_cli_on_a_denali_folder_writes_the_calibrated_sensor_and_holdout(cli_run):
    result, folder = cli_run
    v = result["fit"]["values"]
    assert result["input"]["zones_fitted"] == list(range(9)) and result["input"]["pulse"] == "gaussian"
    assert result["input"]["kind"] == "DENALI folder" and result["input"]["captures"] == 20
    h = result["holdout"]
    fit_pos, test_pos = split_positions([p for ps in FOLDERS.values() for p in ps], 0.75, 1)
    assert h["positions_holdout"] == test_pos.tolist() and h["positions_fit"] == fit_pos.tolist()
    assert h["n_holdout"] == REPEATS * len(test_pos) and len(h["peak_bin_error"]) == 9 * h["n_holdout"]
    assert h["peak_bin_error_max_abs"] == 0
    assert h["shape_l1_mean"] < 0.02
    assert h["amplitude_ratio_median"] == pytest.approx(1.0, abs=0.01)
    s = resolve_sensor(str(folder / "cal.toml"))
    assert s.name == "gauss-3x3-calibrated"
    assert s.bin_width_ps == pytest.approx(v["bin_width_ps"])
    assert s.start_offset_ps == pytest.approx(v["start_offset_ps"])
    # lights-off floors give the dark rate, lights-on floors the ambient rate on top
    floor = s.iterations * s.bin_width_ps * 1e-12
    assert s.dark_rate_hz * floor == pytest.approx(DARK, rel=0.02)
    assert s.ambient_rate_hz * floor == pytest.approx(AMBIENT, rel=0.03)
    assert (folder / "cal.png").stat().st_size > 10_000


def test_cli_on_a_capture_store_with_a_filter(folder, tmp_path, capsys):
    from nlosplan.data.denali_io import import_denali
    from nlosplan.data.store import CaptureStore

    store = tmp_path / "denali.sqlite"
    with CaptureStore(store, synchronous="NORMAL") as st:
        import_denali(folder, st)
    start = "bin_width_ps=91,start_offset_ps=-1150,pulse_fwhm_ps=300,crosstalk=2e-4"
    code = main(["calibrate", str(store), "--where", "object=A,position=0|19|33", "--sensor", "tmf8828-3x3-short",
                 "--pulse", "gaussian", "--steps", "scale", "--start", start, "--out", "", "--plot", "", "--bootstrap", "5",
                 "--json"])
    assert code == 0
    result = json.loads(capsys.readouterr().out)
    # the model is right here: resampling the 6 captures spreads the scale about as much as photon counting
    boot = result["bootstrap"]
    assert boot["resamples"] == 5 and list(boot["errors"]) == ["photon_scale"]
    assert 0.2 < boot["errors"]["photon_scale"] / result["fit"]["errors"]["photon_scale"] < 5.0
    assert result["input"]["captures"] == 3 * REPEATS and result["input"]["objects"] == ["A_8in"]
    assert result["input"]["kind"] == "capture store" and result["input"]["where"]["position"] == [0, 19, 33]
    assert result["fit"]["fitted"] == ["photon_scale"]
    assert result["fit"]["values"]["photon_scale"] == pytest.approx(TRUE["photon_scale"], rel=0.01)


def test_like_for_like_with_the_fast_simulator():
    """Arrivals of the matching scenes through the fit's model at a sensor's own parameters = the fast simulator."""
    s = preset("tmf8828-3x3-short").replace(saturation=False, crosstalk=3e-4, jitter_fwhm_ps=120.0,
                                            pulse_fwhm_ps=50.0, ambient_rate_hz=1e6)
    keys = [("A", "8in", 19), ("7", "4in", 80), ("NOOBJECT", "8in", 3)]
    times, weights = scene_arrivals(keys, s)
    assert times.shape[:2] == (3, 9) and np.all(weights >= 0)
    scenes = [matching_scene(*k, lights="on") for k in keys[:2]]
    objects = FastSimulator(scenes, s, dtype="float64").expected(parts=True)
    rig = FastSimulator(matching_scene(*keys[2], lights="on"), s, dtype="float64").expected(parts=True)
    ref = {part: np.concatenate([objects[part], rig[part][None]]).reshape(3, 9, 128) for part in objects}

    def model_counts(w, theta):
        cs = CaptureSet(np.zeros((3, 9, 128)), times, w, s.iterations, tuple(map(str, keys)))
        model = make_model(cs, s.pulse_shape, s.pulse_shape_step_ps, s.pulse_shape_t0_ps, s.bin_width_ps,
                           s.start_offset_ps)
        return np.asarray(model(np.asarray(theta)))

    noise = (s.dark_rate_hz + s.ambient_rate_hz) * s.bin_width_ps * 1e-12 * s.iterations
    theta = [s.photon_scale, math.hypot(s.pulse_fwhm_ps, s.jitter_fwhm_ps), s.bin_width_ps, s.start_offset_ps,
             noise, s.crosstalk]
    mu, truth = model_counts(weights, theta), ref["counts"]
    l1 = np.abs(mu - truth).sum((1, 2)) / truth.sum((1, 2))
    assert np.all(l1 < 0.003), l1  # whole histograms, 0.13 % measured
    assert np.all(np.abs(mu.max(-1) - truth.max(-1)) < 0.004 * truth.max(-1))  # wall peaks
    # that 0.13 % is the simulator's node grid (4 nodes per bin; the model has 8): with 8 it is the same numbers
    eight = FastSimulator(scenes, s, dtype="float64", fidelity={"time_oversample": 8}).expected().reshape(2, 9, 128)
    assert np.abs(mu[:2] - eight).sum() / eight.sum() < 2e-5
    # the three-bounce part alone (arrivals after the zone_sub**2 = 16 first-bounce sub-rays)
    only = model_counts(np.where(np.arange(weights.shape[-1]) < 16, 0.0, weights), theta[:4] + [0.0, 0.0])
    obj = ref["object"]
    share = obj.sum((1, 2)) / ref["direct"].sum((1, 2))
    assert np.all((2e-4 < share[:2]) & (share[:2] < 3e-3)) and share[2] == 0  # the object: ~1e-3 of the wall return
    assert np.all(np.abs(only - obj).sum((1, 2))[:2] / obj.sum((1, 2))[:2] < 0.01)
    assert np.all(only[2] == 0.0)


def test_wall_zones_and_backgrounds():
    assert wall_zones(preset("tmf8828-3x3-short")) == list(range(9))
    assert matching_scene("NOOBJECT", "4in", 7).objects == ()
    mount = matching_scene("NOOBJECTMOUNT", "4in", 7)
    assert [o.name for o in mount.objects] == ["object mount", "mount plate"]
    assert all(o.reflectance == "lambertian" for o in mount.objects)


def _one_line_error(capsys, argv, message):
    code = main(["calibrate", *argv, "--out", "", "--plot", ""])
    err = capsys.readouterr().err.strip()
    assert code == 2
    assert message in err and len(err.splitlines()) == 1, err


def test_not_a_denali_folder_is_one_line(tmp_path, capsys):
    (tmp_path / "photos").mkdir()
    (tmp_path / "A_8inch_3x3_lightoff_NLOSdata").mkdir()  # no spad_histogram
    _one_line_error(capsys, [str(tmp_path)], f"{tmp_path} is not a DENALI-layout folder")


@pytest.mark.parametrize("argv, message", [
    (["--sensor", "tmf8828-8x8-short"], "the captures have 3x3 zones but sensor tmf8828-8x8-short has 8x8"),
    (["--where", "object=B"], "no captures in "),
    (["--where", "colour=red"], "cannot filter captures by 'colour'"),
    (["--lights", "off"], "--lights applies to JSON plane captures only"),
    (["--noise", "global"], "--noise global fits one floor, but the captures mix lights on and off"),
    (["--steps", "shift"], "unknown calibration step(s) shift"),
    (["--zones", "12"], "--zones '12' must be flat zone indices 0..8"),
    (["--fidelity", "ultra"], "unknown fidelity 'ultra'"),
    (["--pulse", "shape", "--sensor", "SENSOR_WITHOUT_SHAPE"], "has no measured pulse shape; use --pulse gaussian"),
])
def test_bad_denali_input_exits_2_with_one_line(folder, tmp_path, capsys, argv, message):
    base = tmp_path / "gauss.toml"
    _base_sensor().save(base)
    argv = [str(base) if a == "SENSOR_WITHOUT_SHAPE" else a for a in argv]
    _one_line_error(capsys, [str(folder), *argv], message)


def test_mixed_zone_modes_and_json_only_flags_are_one_line(folder, tmp_path, capsys):
    root = tmp_path / "mixed"
    for name, n in (("A_8inch_3x3_lightoff_NLOSdata", 3), ("A_8inch_8x8_lightoff_NLOSdata", 8)):
        (root / name / "spad_histogram").mkdir(parents=True)
        np.save(root / name / "spad_histogram" / "000.npy", np.ones((1, n, n, 128), np.int64))
    _one_line_error(capsys, [str(root)], "mix zone modes 3x3, 8x8; calibrate one at a time, e.g. --where zones=3x3")
    json_file = tmp_path / "plane.json"
    json_file.write_text("[]")
    _one_line_error(capsys, [str(json_file), "--where", "lights=off"], "--where applies to a DENALI folder or a "
                                                                         "capture store")
    _one_line_error(capsys, [str(tmp_path / "missing.sqlite")], "capture store")


@pytest.mark.slow
def test_default_cli_with_the_presets_measured_pulse_shape(tmp_path, capsys):
    """The folder's stored sensor (DENALI's 3x3 unit, its measured pulse shape) and every default: ~20-30 s."""
    truth = preset("denali-tmf8828-3x3").replace(pulse_fwhm_ps=120.0, bin_width_ps=91.0, start_offset_ps=-1150.0,
                                                photon_scale=2.0, crosstalk=2e-4, saturation=False)
    rng = np.random.default_rng(0)
    positions = FOLDERS["A_8inch_3x3_lightoff_NLOSdata"]
    d = tmp_path / "data" / "A_8inch_3x3_lightoff_NLOSdata" / "spad_histogram"
    d.mkdir(parents=True)
    mean = FastSimulator([matching_scene("A", "8in", p) for p in positions], truth,
                         fidelity={"time_oversample": 8}).expected()
    for p, m in zip(positions, mean):
        np.save(d / f"{p:03d}.npy", rng.poisson(np.broadcast_to(m, (REPEATS,) + m.shape)))
    assert main(["calibrate", str(tmp_path / "data"), "--out", str(tmp_path / "cal.toml"), "--plot", "",
                 "--json"]) == 0
    result = json.loads(capsys.readouterr().out)
    assert result["base"] == "denali-tmf8828-3x3" and result["input"]["pulse"] == "shape"
    v, e = result["fit"]["values"], result["fit"]["errors"]
    for name in ("photon_scale", "pulse_fwhm_ps", "bin_width_ps", "start_offset_ps", "crosstalk"):
        truth_value = getattr(truth, name)
        # at DENALI's 10.24 M iterations Fisher errors are ~1e-4 relative; the fit's tables reproduce the simulator
        # to ~0.1 %, so 0.2 % of the value is the model's own floor beside 4 sigma (5 % for the crosstalk, whose
        # small peak sits on DENALI's floor of ~1,200 counts per bin)
        tol = 4 * e[name] + (5e-2 if name == "crosstalk" else 2e-3) * abs(truth_value)
        assert abs(v[name] - truth_value) < tol, (name, v[name], truth_value, e[name])
    s = resolve_sensor(str(tmp_path / "cal.toml"))
    assert s.pulse_shape == pytest.approx(truth.pulse_shape) and s.bin_width_ps == pytest.approx(v["bin_width_ps"])
    # lights off: the floor (DENALI's ~1,200 counts/bin, on the few bins before the crosstalk) becomes the dark rate
    assert s.dark_rate_hz == pytest.approx(truth.dark_rate_hz, rel=0.15)
