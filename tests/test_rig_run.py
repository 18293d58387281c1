"""``nlosplan rig run`` end to end on the pty emulators: closed loop, approval gate, resume, errors."""

import io
import json

import pytest

from nlosplan.cli import main

ARGS = ["rig", "run", "--emulate", "--planner", "active", "--budget", "4", "--batch", "2", "--grid", "3",
        "--repeats", "1", "--settle", "0", "--quiet"]


def test_closed_loop_with_approval_runs_the_approved_batch_and_stops_at_a_refusal(tmp_path, monkeypatch, capsys):
    """The approval gate (on the datasheet unit's long range: plain scenes, a third of the time; the slow resume test
    runs the default DENALI-calibrated model)."""
    monkeypatch.setattr("sys.stdin", io.StringIO("y\nn\n"))
    out = tmp_path / "out"
    code = main(ARGS + ["--range", "long", "--approve", "--store", str(tmp_path / "loop.db"), "--out", str(out), "--json"])
    cap = capsys.readouterr()
    assert code == 0, cap.err
    res = json.loads(cap.out)
    assert res["planner"]["captures"] == 2 and res["executor"]["captured"] == 2
    assert res["finished"] == "batch not approved"
    assert len(res["history"]) == 1 and res["history"][0]["captures"] == 2
    assert sorted(p.name for p in out.glob("batch_*.png")) == ["batch_000.png", "batch_001.png"]
    assert cap.err.count("move the gantry to these 2 positions? [y/N]") == 2
    state = json.loads((out / "planner.json").read_text())
    assert [p["status"] for p in state["proposals"]] == ["done", "done", "rejected", "rejected"]


@pytest.mark.slow
def test_rerunning_the_same_command_resumes_from_the_store(tmp_path, capsys):
    argv = ARGS + ["--store", str(tmp_path / "loop.db"), "--out", str(tmp_path / "out"), "--json"]
    assert main(argv) == 0
    first = json.loads(capsys.readouterr().out)
    assert first["executor"]["captured"] == 4 and first["finished"] == "budget of 4 positions spent"
    assert main(argv) == 0
    again = json.loads(capsys.readouterr().out)
    assert again["executor"]["captured"] == 0 and again["executor"]["resumed"] == 4
    assert again["planner"]["calibration"]["theta"] == pytest.approx(first["planner"]["calibration"]["theta"])
    assert again["run_id"] == first["run_id"]
    planner_state = json.loads((tmp_path / "out" / "planner.json").read_text())
    assert len(planner_state["observations"]) == 4


def test_bad_input_exits_2_with_one_line(tmp_path, capsys):
    assert main(["rig", "run", "--store", str(tmp_path / "x.db")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "give --lidar PORT and --gantry PORT, or --emulate" in err
    assert main(["rig", "run", "--emulate", "--planner", "best", "--store", str(tmp_path / "x.db")]) == 2
    assert "invalid choice: 'best'" in capsys.readouterr().err
