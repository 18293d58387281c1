"""``nlosplan rig``: help with examples, one-line errors with exit 2, capture/status/dry-run output."""

import json

import pytest

from nlosplan.cli import main


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
