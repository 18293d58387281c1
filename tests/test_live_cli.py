"""``nlosplan serve`` and ``--live``: bad input (one line, exit 2, before any work), the token rules, the
approval prompt that takes the first answer from the terminal or a page, and the server answering HTTP."""

import json
import os
import socket
import subprocess
import sys
import threading
import time
import urllib.request
from pathlib import Path

import numpy as np
import pytest

from nlosplan.cli import main
from nlosplan.cli.live import ask_approval
from nlosplan.cli.serve import resolve_page, with_token
from nlosplan.data.store import CaptureStore
from nlosplan.planner.capture.approval import Answer, post_request, submit_answer
from nlosplan.sensor_models import preset

ROOT = Path(__file__).resolve().parents[1]


def one_line_error(capsys, argv, *must):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    for m in must:
        assert m in err, err
    return err


@pytest.fixture
def busy_port():
    s = socket.socket()
    s.bind(("127.0.0.1", 0))
    s.listen(1)
    yield s.getsockname()[1]
    s.close()


@pytest.fixture
def store(tmp_path):
    path = tmp_path / "runs.db"
    with CaptureStore(path) as st:
        st.put(np.ones((3, 3, 128), np.int64), dict(object="A", size="8in", position=0, lights="off", repeat=0,
                                                    source="rig", capture_id="r/000000"),
               sensor=preset("tmf8828-3x3-short"), meta={"run_id": "r", "step": 0, "commanded_mm": [0, 0]})
    return path


def test_serve_refuses_a_path_that_is_neither_a_design_folder_nor_a_store(tmp_path, capsys):
    (tmp_path / "notes.txt").write_text("hello")
    one_line_error(capsys, ["serve", str(tmp_path)], "is neither a design output folder", "nor a capture store")
    one_line_error(capsys, ["serve", str(tmp_path / "notes.txt")], "is neither a design output folder")
    one_line_error(capsys, ["serve", str(tmp_path / "missing")], "does not exist")
    import sqlite3

    sqlite3.connect(tmp_path / "other.sqlite").execute("CREATE TABLE t (x)").connection.commit()
    one_line_error(capsys, ["serve", str(tmp_path / "other.sqlite")], "nor a capture store")


def test_serve_on_a_port_in_use_exits_2(store, busy_port, capsys):
    one_line_error(capsys, ["serve", str(store), "--port", str(busy_port)], f"port {busy_port} on 127.0.0.1 is in use")


def test_a_non_loopback_host_with_actions_needs_a_token(store, tmp_path, capsys):
    (tmp_path / "run").mkdir()
    one_line_error(capsys, ["serve", str(store), "--planner", str(tmp_path / "run"), "--host", "0.0.0.0",
                            "--no-token"], "--host 0.0.0.0 with --no-token", "move the gantry")
    one_line_error(capsys, ["serve", str(store), "--token", "long-enough"], "can be read by every user", "(ps)")
    one_line_error(capsys, ["serve", str(store), "--token", "-", "--no-token"], "exclude each other")
    page = resolve_page(store, planner=tmp_path / "run")
    assert page.actions and page.kind == "rig"
    assert with_token(page, "127.0.0.1", None, False).token       # a random token by default
    assert with_token(page, "127.0.0.1", None, True).token is None   # loopback: --no-token allowed
    assert with_token(page, "10.0.0.5", "chosen-token", False).token == "chosen-token"
    assert with_token(resolve_page(store, planner=tmp_path / "run", read_only=True), "0.0.0.0", None, True).token \
        is None                                                      # read-only: nothing to protect
    assert not resolve_page(store).actions                           # no run folder: no approval gate


def test_a_rig_run_folder_without_its_store(tmp_path, capsys):
    (tmp_path / "planner.json").write_text("{}")
    one_line_error(capsys, ["serve", str(tmp_path)], "has not finished", "nlosplan serve STORE --planner")


@pytest.mark.parametrize("argv", [
    ["design", "--quick", "--out", "{tmp}/d", "--live", "{port}"],
    ["rig", "capture", "--emulate", "--positions", "0", "--store", "{tmp}/c.db", "--live", "{port}"],
    ["rig", "run", "--emulate", "--budget", "2", "--store", "{tmp}/r.db", "--out", "{tmp}/r", "--live",
     "127.0.0.1:{port}"],
])
def test_live_on_a_port_in_use_stops_before_any_work(argv, tmp_path, busy_port, capsys):
    argv = [a.format(tmp=tmp_path, port=busy_port) for a in argv]
    one_line_error(capsys, argv, f"port {busy_port} on 127.0.0.1 is in use")
    assert list(tmp_path.iterdir()) == []        # no output folder, no store: nothing started


def test_live_address_is_checked(capsys):
    assert main(["design", "--live", "nope"]) == 2
    assert "give PORT or HOST:PORT" in capsys.readouterr().err
    assert main(["design", "--live", "70000"]) == 2
    assert "out of range" in capsys.readouterr().err


def _pipe_stdin():
    r, w = os.pipe()
    return os.fdopen(r, "r"), os.fdopen(w, "w")


def test_the_prompt_takes_the_first_answer_terminal_or_page(tmp_path):
    req = post_request(tmp_path, run_id="r", batch=0, ids=["c00000"])
    stdin, typing = _pipe_stdin()
    threading.Timer(0.3, lambda: submit_answer(tmp_path, req["request_id"],
                                               Answer("approve", drop=["c00000"], add=[4], by="page"))).start()
    got = ask_approval(req, tmp_path, live=True, stdin=stdin, poll_s=0.05)
    assert got == Answer("approve", ("c00000",), (4,), "page")
    req = post_request(tmp_path, run_id="r", batch=1, ids=["c00001"])
    typing.write("y\n")
    typing.flush()
    assert ask_approval(req, tmp_path, live=True, stdin=stdin, poll_s=0.05) == Answer("approve", by="terminal")
    assert not submit_answer(tmp_path, req["request_id"], Answer("refuse", by="page"))   # too late
    typing.close()                                      # no terminal any more (end of input)
    req = post_request(tmp_path, run_id="r", batch=2, ids=["c00002"])
    threading.Timer(0.3, lambda: submit_answer(tmp_path, req["request_id"], Answer("refuse", by="page"))).start()
    assert ask_approval(req, tmp_path, live=True, stdin=stdin, poll_s=0.05).decision == "refuse"
    req = post_request(tmp_path, run_id="r", batch=3, ids=["c00003"])
    assert ask_approval(req, tmp_path, live=False, stdin=stdin, poll_s=0.05) == Answer("refuse", by="terminal")


def test_serve_answers_http_on_loopback_and_stops_on_sigterm_with_143(store):
    proc = subprocess.Popen([sys.executable, "-m", "nlosplan", "serve", str(store), "--port", "0"],
                            stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    try:
        line = proc.stderr.readline()
        assert "rig page of" in line and "http://127.0.0.1:" in line and "token" not in line   # no actions: no token
        url = line.split(" at ")[1].split()[0]
        deadline = time.monotonic() + 120
        while True:
            try:
                body = urllib.request.urlopen(url, timeout=30).read().decode()
                break
            except OSError:
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        assert "bokeh" in body.lower() and "<script" in body
        static = [s for s in body.split('"') if "/static/js/bokeh" in s]
        assert static and all(not s.startswith("http") or s.startswith("http://127.0.0.1") for s in static)
    finally:
        proc.terminate()
        assert proc.wait(timeout=30) == 143        # 128 + SIGTERM: stopped by the event loop, not killed
        assert proc.stderr.read().splitlines()[-1] == "nlosplan serve: stopped (SIGTERM)"


@pytest.mark.slow  # two emulated rig captures (~1 min)
def test_bench_live_times_a_run_with_and_without_a_page(tmp_path):
    from nlosplan.reports.live.bench import bench_live

    res = bench_live(tmp_path, rounds=1, positions="0-1", repeats=1, pages=1)
    (row,) = res["rounds"]
    assert row["pages"] == 1                  # a session was open on the live run's page
    assert res["captures"] == 2 and row["plain_s"] > 0 and row["live_s"] > 0
    assert res["median_ratio"] == pytest.approx(row["live_s"] / row["plain_s"])
    assert sorted(p.name for p in tmp_path.glob("*.db")) == ["round0_live.db", "round0_plain.db"]


@pytest.mark.slow  # two emulated closed-loop runs (~2 min)
def test_an_edit_made_on_the_page_is_replayed_when_the_run_is_rerun(tmp_path, monkeypatch, capsys):
    """A run edited from the page (here a thread writing the page's answers), killed by a refusal, rerun:
    the edited batch runs again as approved (resumed from the store, nothing moves), the next is asked."""
    import io

    from nlosplan.planner.capture.approval import read_request

    out, db = tmp_path / "out", tmp_path / "loop.db"
    argv = ["rig", "run", "--emulate", "--planner", "active", "--budget", "4", "--batch", "2", "--grid", "3",
            "--repeats", "1", "--settle", "0", "--approve", "--store", str(db), "--out", str(out), "--json"]
    answered = []

    def page():
        deadline = time.monotonic() + 600
        while len(answered) < 2 and time.monotonic() < deadline:
            req = read_request(out)
            if req and req["status"] == "pending" and req["request_id"] not in answered:
                state = json.loads((out / "planner.json").read_text())
                taken = {p["index"] for p in state["proposals"]}
                free = next(i for i in range(len(state["space"]["points_mm"])) if i not in taken)
                answer = (Answer("approve", drop=[req["ids"][0]], add=[free], by="page") if not answered
                          else Answer("refuse", by="page"))
                submit_answer(out, req["request_id"], answer)
                answered.append(req["request_id"])
            time.sleep(0.1)

    thread = threading.Thread(target=page, daemon=True)
    thread.start()
    monkeypatch.setattr("sys.stdin", io.StringIO(""))   # no terminal: the page answers
    assert main(argv + ["--live", "0"]) == 0
    thread.join(timeout=5)
    first = json.loads(capsys.readouterr().out)
    assert first["finished"] == "batch not approved" and first["executor"]["captured"] == 2
    monkeypatch.setattr("sys.stdin", io.StringIO("n\n"))
    assert main(argv) == 0
    cap = capsys.readouterr()
    again = json.loads(cap.out)
    assert "batch 0 was approved by the page" in cap.err and "with edits" in cap.err
    assert cap.err.count("move the gantry to these") == 1      # only batch 1 was asked
    assert (again["executor"]["captured"], again["executor"]["resumed"]) == (0, 2)
    assert again["planner"]["calibration"]["theta"] == pytest.approx(first["planner"]["calibration"]["theta"])
