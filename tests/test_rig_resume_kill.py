"""kill -9 in the middle of an emulated run, then the same command again: nothing lost, nothing doubled."""

import os
import signal
import subprocess
import sys
import time

from nlosplan.data.store import CaptureStore


# ``nlosplan rig`` alone (the rig CLI module's own parser): the whole command would also import torch & co.
# (a UserError ends it as the command does: one line on stderr, exit 2)
RIG_ONLY = ("import argparse, sys; from nlosplan.cli import rig; from nlosplan.errors import UserError; "
            "p = argparse.ArgumentParser(); rig.add(p.add_subparsers()); a = p.parse_args(sys.argv[1:])\n"
            "try:\n    sys.exit(a.func(a))\n"
            "except UserError as e:\n    print(f'nlosplan: error: {e}', file=sys.stderr); sys.exit(2)")


def _cmd(store, *extra):
    return [sys.executable, "-c", RIG_ONLY, "rig", "capture", "--emulate", "--positions", "0-5", "--repeats", "2",
            "--settle", "0.05", "--time-scale", "50", "--store", str(store), "--run", "k9", "--json", *extra]


def _count(store) -> int:
    if not store.exists():
        return 0
    try:
        with CaptureStore(store, create=False) as st:
            return st.count()
    except Exception:  # noqa: BLE001 - the writer may be creating the file right now
        return 0


def test_kill_9_mid_run_then_resume_completes_without_loss_or_duplicates(tmp_path):
    store = tmp_path / "runs.db"
    proc = subprocess.Popen(_cmd(store), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 300   # start-up (imports, compiling the emulated sensor) under load
        while _count(store) < 4 and time.monotonic() < deadline and proc.poll() is None:
            time.sleep(0.05)
        assert proc.poll() is None, "the run ended before it could be killed"
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(timeout=10)
    finally:
        if proc.poll() is None:
            proc.kill()
    before = _count(store)
    assert 4 <= before < 12
    with CaptureStore(store, create=False) as st:
        assert st.integrity_check() == "ok"
    # the killed session never parked: the gantry's counters restart wherever the carriage stands, so the resume
    # asks the operator first (one line, nothing moved, nothing stored) ...
    out = subprocess.run(_cmd(store), capture_output=True, text=True, timeout=300)
    assert out.returncode == 2 and out.stderr.count("\n") == 1, out.stderr
    assert "(run k9, opened " in out.stderr and "did not end (killed?)" in out.stderr
    assert "rerun with --origin-confirmed; nothing moved" in out.stderr and _count(store) == before
    # ... and resumes once told the carriage is at the origin
    out = subprocess.run(_cmd(store, "--origin-confirmed"), capture_output=True, text=True, timeout=300)
    assert out.returncode == 0, out.stderr
    import json

    summary = json.loads(out.stdout)
    assert summary["resumed"] == before and summary["captured"] == 12 - before and summary["completed"]
    with CaptureStore(store, create=False) as st:
        lab = st.labels()
        assert len(lab) == 12 and lab["capture_id"].is_unique
        assert sorted(lab["capture_id"]) == [f"k9/{s:06d}" for s in range(12)]
        assert sorted(zip(lab["position"], lab["repeat"])) == [(p, r) for p in range(6) for r in range(2)]
