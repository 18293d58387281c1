"""``nlosplan rig``: real and emulated devices mixed, Telemetrix gantries, and every rig failure as one line.

Each bad-input case runs the CLI on a store that already holds captures and checks: exit 2, one line on
stderr, no traceback, the stored captures unchanged. "Real" devices here are ports the test opens itself
(emulators, a silent port, a port that sends noise), given to the CLI as ``--gantry``/``--lidar``.
"""

import hashlib
import json
import shutil
import sqlite3
import time

import numpy as np
import pytest

from nlosplan.cli import main
from nlosplan.hardware.emulators import EmulatedGrbl, EmulatedTelemetrix, EmulatedTMF8828
from nlosplan.data.store import CaptureStore
from rig_ports import NoisePort, SilentPort

QUICK = ["--positions", "0,1", "--repeats", "1", "--settle", "0", "--json"]


def _digest(path) -> dict:
    """{capture key: sha256 of its histogram and metadata}."""
    out = {}
    with CaptureStore(path, create=False) as st:
        for c in st.iter_captures():
            h = hashlib.sha256(np.ascontiguousarray(c.histogram).tobytes())
            h.update(json.dumps(c.meta, sort_keys=True, default=str).encode())
            out[c.key] = h.hexdigest()
    return out


def _kept(before: dict, after: dict, added: int = 0) -> bool:
    """Every capture stored before is still there, unchanged; ``added`` new ones."""
    return all(after.get(k) == v for k, v in before.items()) and len(after) == len(before) + added


@pytest.fixture(scope="module")
def filled_store(tmp_path_factory):
    """A store holding 2 captures of an earlier emulated run."""
    path = tmp_path_factory.mktemp("store") / "runs.db"
    assert main(["rig", "capture", "--emulate", "--time-scale", "50", "--store", str(path), *QUICK]) == 0
    return path


@pytest.fixture
def store(filled_store, tmp_path):
    path = tmp_path / "runs.db"
    shutil.copy(filled_store, path)
    return path


def _fails(capsys, store, argv, message, added=0):
    before = _digest(store)
    t0 = time.monotonic()
    code = main(["rig", "capture", "--store", str(store), *argv])
    took = time.monotonic() - t0
    out, err = capsys.readouterr()
    assert code == 2, err
    assert err.count("\n") == 1 and "Traceback" not in err and message in err, err
    assert _kept(before, _digest(store), added)
    return err, took


def _flat_histograms(zones, range_mode):
    n = int(zones[0])
    return np.full((n, n, 128), 50.0), 100.0


def test_telemetrix_gantry_emulated_with_the_sensor(capsys, tmp_path):
    store = tmp_path / "t.db"
    code = main(["rig", "capture", "--emulate", "--gantry-kind", "telemetrix", "--time-scale", "50",
                 "--store", str(store), *QUICK])
    out, err = capsys.readouterr()
    assert code == 0, err
    assert json.loads(out)["finalize"] == ["sensor stopped", "gantry parked at (0, 0) mm"]
    with CaptureStore(store, create=False) as st:
        caps = list(st.iter_captures())
    assert len(caps) == 2
    for c in caps:
        m = c.meta
        assert m["gantry"]["kind"] == "telemetrix" and m["gantry"]["firmware"] == "5.4.4"
        assert m["gantry"]["x"] == {"step_pin": 2, "dir_pin": 5, "steps_per_mm": 2850 / 28, "flip": False}
        assert m["reported_mm"] == pytest.approx(m["commanded_mm"], abs=m["gantry"]["step_mm"][0])
        assert m["gantry_raw"]["steps"] == [round(v * 2850 / 28) for v in m["commanded_mm"]]


def test_emulated_telemetrix_gantry_with_a_real_sensor_port(capsys, tmp_path):
    """--emulate gantry: the gantry is emulated, the sensor is whatever answers on --lidar."""
    with EmulatedTMF8828(_flat_histograms, frame_period_s=0.02) as lidar:
        code = main(["rig", "capture", "--emulate", "gantry", "--gantry-kind", "telemetrix", "--lidar", lidar.port,
                     "--time-scale", "50", "--store", str(tmp_path / "m.db"), *QUICK])
    out, err = capsys.readouterr()
    assert code == 0, err
    with CaptureStore(tmp_path / "m.db", create=False) as st:
        lab = st.labels()
        caps = list(st.iter_captures())
    assert list(lab["source"]) == ["rig", "rig"] and all(c.meta["emulated"] == ["gantry"] for c in caps)
    assert all(abs(c.histogram.mean() - 50) < 2 for c in caps)   # the port's own histograms, not the simulator's


def test_auto_finds_a_telemetrix_gantry_on_its_port(capsys, tmp_path):
    with EmulatedTelemetrix(time_scale=50) as gantry:
        code = main(["rig", "capture", "--emulate", "lidar", "--gantry", gantry.port, "--gantry-kind", "auto",
                     "--store", str(tmp_path / "a.db"), *QUICK])
    out, err = capsys.readouterr()
    assert code == 0, err and json.loads(out)["captured"] == 2
    with CaptureStore(tmp_path / "a.db", create=False) as st:
        assert {c.meta["gantry"]["kind"] for c in st.iter_captures()} == {"telemetrix"}


@pytest.mark.parametrize("argv, message", [
    (["--emulate", "lidar", "--lidar", "/dev/ttyACM0"], "--lidar /dev/ttyACM0 and --emulate lidar both name the lidar"),
    (["--emulate", "--gantry", "/dev/ttyUSB0"], "--gantry /dev/ttyUSB0 and --emulate both both name the gantry"),
    (["--emulate", "lidar"], "give --gantry PORT for the real gantry, or --emulate gantry"),
    (["--emulate", "lidar", "--baud", "115200", "--gantry", "x"], "--baud is the real TMF8828's baud rate"),
    (["--emulate", "lidar", "--gantry", "x", "--time-scale", "5"], "--time-scale speeds up an emulated gantry"),
    (["--emulate", "gantry", "--lidar", "x", "--seed", "3"], "--seed seeds the emulated sensor's noise"),
    (["--emulate", "lidar", "--gantry", "x", "--emulate-faults", "alarm=2"], "gantry faults and need an emulated"),
    (["--emulate", "gantry", "--lidar", "x", "--emulate-faults", "garble=5"], "sensor faults need an emulated sensor"),
    (["--emulate", "--gantry-kind", "auto"], "--gantry-kind auto probes a real port"),
    (["--emulate", "--rig-file", "r.toml"], "--rig-file describes a Telemetrix gantry"),
    (["--emulate", "--gantry-kind", "telemetrix", "--home"], "--home and --unlock are GRBL's"),
    (["--emulate", "--gantry-kind", "telemetrix", "--work-offset", "keep"], "--work-offset is GRBL's"),
    (["--emulate", "--work-offset", "middle"], "--work-offset 'middle': use auto, keep, or X,Y"),
])
def test_flags_that_do_not_apply_are_errors(capsys, tmp_path, argv, message):
    code = main(["rig", "capture", "--store", str(tmp_path / "x.db"), *argv])
    err = capsys.readouterr().err
    assert code == 2 and message in err and err.count("\n") == 1 and "Traceback" not in err
    assert not (tmp_path / "x.db").exists()


def test_wrong_silent_and_noisy_gantry_ports(capsys, store):
    _fails(capsys, store, ["--emulate", "lidar", "--gantry", "/nonexistent/ttyUSB9", *QUICK],
           "cannot open serial port '/nonexistent/ttyUSB9'")
    with SilentPort() as port:
        err, took = _fails(capsys, store, ["--emulate", "lidar", "--gantry", port.port, *QUICK],
                           "no answer from a gantry on")
    assert "the rig did not open: nothing moved" in err and took < 10
    with NoisePort() as port:
        _fails(capsys, store, ["--emulate", "lidar", "--gantry", port.port, *QUICK], "answers, but not like GRBL 1.1")
        _fails(capsys, store, ["--emulate", "lidar", "--gantry", port.port, "--gantry-kind", "telemetrix", *QUICK],
               "answers, but not like Telemetrix4Arduino")


def test_wrong_firmware_on_the_gantry_port_both_ways(capsys, store):
    with EmulatedGrbl() as grbl:
        _fails(capsys, store, ["--emulate", "lidar", "--gantry", grbl.port, "--gantry-kind", "telemetrix", *QUICK],
               "not Telemetrix4Arduino: use --gantry-kind grbl")
    with EmulatedTelemetrix(reset_on_open=False) as tmx:   # a board that keeps running answers the request
        _fails(capsys, store, ["--emulate", "lidar", "--gantry", tmx.port, *QUICK],
               "runs Telemetrix4Arduino 5.4.4, not GRBL: use --gantry-kind telemetrix")
    with EmulatedTelemetrix() as tmx:                       # one that resets loses it while it boots
        _fails(capsys, store, ["--emulate", "lidar", "--gantry", tmx.port, *QUICK],
               "a Telemetrix4Arduino board that reset as the port opened answers no GRBL request: "
               "--gantry-kind telemetrix or auto")


def test_bad_rig_file_and_limits_outside_the_machine_space(capsys, store, tmp_path):
    rig = tmp_path / "rig.toml"
    rig.write_text("[telemetrix.x]\nsteps_per_mm = 0\n")
    _fails(capsys, store, ["--emulate", "--gantry-kind", "telemetrix", "--rig-file", str(rig), *QUICK],
           "telemetrix x.steps_per_mm = 0")
    # what Telemetrix4Arduino's 16-bit ints cannot represent is refused before anything moves
    rig.write_text("[telemetrix]\nmax_speed = 65535\n")
    _fails(capsys, store, ["--emulate", "--gantry-kind", "telemetrix", "--rig-file", str(rig), *QUICK],
           "max_speed = 65535 in " + str(rig) + " must be an integer 1..32767 steps/s: Telemetrix4Arduino reads it "
           "as a 16-bit AVR int (above 32767 it arrives negative; 65535 runs at 1 step/s)")
    _fails(capsys, store, ["--emulate", "--gantry-kind", "telemetrix", "--limits", "0:330,0:320", *QUICK],
           "gantry limit x = 330 mm is 33,589 steps from origin_mm 0 mm; Telemetrix4Arduino decodes step "
           "targets as 16-bit AVR ints (+-32,767 steps = x -321.9..321.9 mm at 101.79 steps/mm; beyond, it drives "
           "the other way): narrow --limits or move origin_mm")
    with EmulatedGrbl(settings={22: 1, 20: 1, 130: 200, 131: 320}) as grbl:
        _fails(capsys, store, ["--emulate", "lidar", "--gantry", grbl.port, "--unlock", *QUICK],
               "gantry limits x 0..320 mm map to machine x -200..120 mm (work offset -200 mm), outside GRBL's "
               "machine space x -200..0 mm ($130=200, homing on, soft limits on): raise $130 or narrow --limits")


def test_homing_alarm_at_open_is_one_line(capsys, store):
    with EmulatedGrbl(time_scale=500, settings={22: 1, 130: 320, 131: 320}, switches="XY") as grbl:
        err, _ = _fails(capsys, store, ["--emulate", "lidar", "--gantry", grbl.port, "--home", *QUICK],
                        "ALARM:9 (homing fail: could not find the limit switch")
    assert "stock GRBL homes Z first" in err and "nothing moved" in err


def test_silent_and_noisy_sensor_ports_are_named_within_seconds(capsys, store):
    with SilentPort() as port:
        err, took = _fails(capsys, store, ["--emulate", "gantry", "--lidar", port.port, *QUICK],
                           "no answer to command 'h' within 3 s")
    assert took < 10
    with NoisePort() as port:
        err, took = _fails(capsys, store, ["--emulate", "gantry", "--lidar", port.port, *QUICK],
                           "answers command 'h' with noise")
    assert took < 10 and "wrong baud rate" in err


def test_gantry_alarm_during_a_run_says_what_finalize_did(capsys, store):
    err, _ = _fails(capsys, store, ["--emulate", "--time-scale", "50", "--emulate-faults", "alarm=2",
                                    "--positions", "0-3", "--repeats", "1", "--settle", "0", "--run", "al"],
                    "ALARM:1 (hard limit triggered", added=1)
    assert "1 new captures stored" in err and "finalize: sensor stopped; gantry in alarm (ALARM:1): not parked" in err
    assert "rerun the same command with --unlock or --home" in err


def test_full_disk_and_ctrl_c_end_with_the_finalizer_outcome(capsys, store, monkeypatch):
    real_put = CaptureStore.put
    calls = {"n": 0}

    def put(self, *a, **k):
        calls["n"] += 1
        if calls["n"] == 2:
            raise sqlite3.OperationalError("database or disk is full")
        return real_put(self, *a, **k)

    monkeypatch.setattr(CaptureStore, "put", put)
    before = _digest(store)
    argv = ["rig", "capture", "--emulate", "--time-scale", "50", "--positions", "0-3", "--repeats", "1",
            "--settle", "0", "--store", str(store), "--run", "disk"]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "database or disk is full (disk full; the captures committed before" in err
    assert "1 new captures stored" in err and "finalize: sensor stopped; gantry parked at (0, 0) mm" in err
    assert _kept(before, _digest(store), 1)   # what was stored before stays, the capture before the failure too

    def interrupted(self, *a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(CaptureStore, "put", interrupted)
    assert main(argv[:-1] + ["ctrlc"]) == 130
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("nlosplan: interrupted: run ctrlc stopped at step 0")
    assert "finalize: sensor stopped; gantry parked at (0, 0) mm" in err
