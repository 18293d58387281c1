"""``nlosplan rig``: help with examples, one-line errors with exit 2, capture/status/dry-run output."""

import json

import pytest

from nlosplan.cli import main
from nlosplan.data.store import CaptureStore


def _run(capsys, *argv):
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_help_shows_examples(capsys):
    with pytest.raises(SystemExit):
        main(["rig", "capture", "--help"])
    out = capsys.readouterr().out
    assert "nlosplan rig capture --emulate --plan raster" in out and "resumes the run" in out


@pytest.mark.parametrize("argv, message", [
    (["rig", "capture", "--store", "x.db"], "give --lidar PORT and --gantry PORT, or --emulate"),
    (["rig", "dry-run", "--limits", "5:1,0:3"], "each minimum must be below its maximum"),
    (["rig", "dry-run", "--positions", "0-120"], "grid indices run from 0 to 99"),
    (["rig", "dry-run", "--plan", "missing.csv"], "positions file missing.csv does not exist"),
    (["rig", "capture", "--store", "x.db", "--lidar", "a", "--gantry", "b", "--emulate-faults", "drop=3"],
     "--emulate-faults needs --emulate"),
    (["rig", "capture", "--emulate", "--store", "x.db", "--emulate-faults", "melt=1"], "unknown fault 'melt'"),
    (["rig", "status", "--store", "nope.db"], "capture store nope.db does not exist"),
])
def test_bad_input_is_one_line_and_exit_2(capsys, tmp_path, monkeypatch, argv, message):
    monkeypatch.chdir(tmp_path)
    code, out, err = _run(capsys, *argv)
    assert code == 2 and message in err and err.count("\n") == 1 and "Traceback" not in err


def test_dry_run_refuses_a_plan_outside_the_limits(capsys, tmp_path):
    (tmp_path / "p.csv").write_text("x_mm,y_mm\n10,10\n330,10\n")
    code, out, err = _run(capsys, "rig", "dry-run", "--plan", str(tmp_path / "p.csv"), "--repeats", "1", "--json")
    data = json.loads(out)
    assert code == 2 and data["captures"] == 2 and len(data["moves"]) == 2
    assert data["problems"] == ["move 2 to (330.0, 10.0) mm is outside the limits x 0..320, y 0..320 mm"]
    assert "the plan has 1 problem(s)" in err


def test_emulated_capture_then_status(capsys, tmp_path):
    store = str(tmp_path / "emu.db")
    code, out, err = _run(capsys, "rig", "capture", "--emulate", "--positions", "0-2", "--repeats", "2", "--settle",
                          "0", "--time-scale", "50", "--store", store, "--json")
    assert code == 0, err
    data = json.loads(out)
    assert (data["captured"], data["resumed"], data["moves"], data["completed"]) == (6, 0, 3, True)
    run_id = data["run_id"]
    code, out, err = _run(capsys, "rig", "status", "--store", store, "--json")
    (row,) = json.loads(out)["runs"]
    assert (row["run_id"], row["captured"], row["planned"], row["left"], row["positions"]) == (run_id, 6, 6, 0, 3)
    # the same command with more positions is another run (another id); its status lists what is left
    code, out, err = _run(capsys, "rig", "capture", "--emulate", "--positions", "0-2", "--repeats", "2", "--settle",
                          "0", "--time-scale", "50", "--store", store)
    assert code == 0 and "0 captured, 6 already stored" in out
    code, out, err = _run(capsys, "rig", "status", "--store", store, "--run", run_id)
    assert f"{run_id}: 6/6 captured, 0 left" in out


def test_telemetrix_dry_run_moves_only_the_y_motor_from_position_0_to_1(capsys):
    code, out, err = _run(capsys, "rig", "dry-run", "--gantry-kind", "telemetrix", "--plan", "raster", "--positions",
                          "0-1", "--json")
    assert code == 0, err
    data = json.loads(out)
    (m0, m1) = data["moves"]
    assert {"x_mm", "y_mm", "steps"} <= set(m0) and m0["steps"] == {"x": 0, "y": 0}
    # DENALI's order: y is the serpentine axis, on motor 1 (pins 3/6); x (motor 0, pins 2/5) stays
    assert (m1["x_mm"], m1["steps"]["x"]) == (0.0, 0) and m1["steps"]["y"] == 3619 and m1["y_mm"] > 35.5
    assert data["gantry"]["motors"]["x"] == {"motor": 0, "step_pin": 2, "dir_pin": 5,
                                             "steps_per_mm": 2850 / 28, "flip": False}
    code, out, err = _run(capsys, "rig", "dry-run", "--positions", "0-1", "--json")   # GRBL: no steps known
    assert code == 0 and [m["steps"] for m in json.loads(out)["moves"]] == [None, None]


def test_telemetrix_dry_run_refuses_limits_the_firmware_cannot_count(capsys):
    code, out, err = _run(capsys, "rig", "dry-run", "--gantry-kind", "telemetrix", "--limits", "0:320,-330:320")
    assert code == 2 and err.count("\n") == 1 and "Traceback" not in err
    assert ("gantry limit y = -330 mm is 33,589 steps from origin_mm 0 mm; Telemetrix4Arduino decodes step targets "
            "as 16-bit AVR ints (+-32,767 steps = y -321.9..321.9 mm") in err


def test_a_run_that_did_not_park_makes_the_next_one_confirm_the_origin(capsys, tmp_path):
    """A Telemetrix gantry counts from wherever the carriage stands when the port opens (no switches)."""
    store = tmp_path / "t.db"
    base = ["rig", "capture", "--emulate", "--gantry-kind", "telemetrix", "--positions", "0-1", "--repeats", "1",
            "--settle", "0", "--time-scale", "50", "--store", str(store), "--json"]
    code, out, err = _run(capsys, *base, "--no-park")
    assert code == 0, err
    run_id = json.loads(out)["run_id"]
    code, out, err = _run(capsys, "rig", "status", "--store", str(store), "--json")
    (row,) = json.loads(out)["runs"]
    assert row["parked_at_origin"] is False and row["gantry_session"]["end_xy"] == [0.0, 35.5551]
    code, out, err = _run(capsys, "rig", "status", "--store", str(store))
    assert "gantry: left at (0, 35.5551) mm, not at the origin (0, 0) mm" in out
    # the same run again (a resume) and another run both stop before anything moves
    for extra in ([], ["--positions", "2"]):
        code, out, err = _run(capsys, *base, *extra)
        assert code == 2 and err.count("\n") == 1 and "Traceback" not in err, err
        assert (f"the last session on this store (run {run_id}, opened " in err and "left the carriage at "
                "(0, 35.5551) mm, not at the origin (0, 0) mm; this telemetrix gantry counts from wherever the "
                "carriage stands when the port opens: move the carriage to the origin (0, 0) mm and rerun with "
                "--origin-confirmed; nothing moved" in err), err
    with CaptureStore(store) as st:
        assert st.count() == 2
    code, out, err = _run(capsys, *base, "--positions", "2", "--origin-confirmed")
    assert code == 0 and json.loads(out)["finalize"][-1] == "gantry parked at (0, 0) mm", err
    code, out, err = _run(capsys, "rig", "status", "--store", str(store), "--json")
    rows = {r["run_id"]: r for r in json.loads(out)["runs"]}
    new = next(r for rid, r in rows.items() if rid != run_id)
    assert new["parked_at_origin"] is True and new["gantry_session"]["origin_confirmed"] is True
    code, out, err = _run(capsys, *base)            # parked at the origin last time: no question asked
    assert code == 0 and json.loads(out)["resumed"] == 2, err
