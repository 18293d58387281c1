"""Issue 18: interruptions. kill -9 of ``dataset build`` and of ``design`` (then resume) gives what an uninterrupted
run gives, and no worker process outlives a killed ``design`` (local pool or Dask LocalCluster).

These run the real command in a subprocess and take 20-90 s each: marked slow (CI runs them).
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

pytestmark = [pytest.mark.slow,
              pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="process checks read /proc (Linux)")]

ROOT = Path(__file__).resolve().parents[1]
TINY = ('[space]\nzones = ["1x1", "3x3"]\nbin_factors = [1, 2]\naxes = ["zones", "jitter_fwhm_ps"]\n'
        "[search]\ngrid_points = 3\nrefine_steps = 1\nseeds = 1\ncandidates = 1\noptimize_evals = 4\ncurve_seeds = 0\n"
        "[search.fidelity.bound]\ndraws = 60\n[search.fidelity.trained]\nepochs = 4\nbootstrap = 50\n"
        '[scenes]\nobjects = ["A", "S", "circle"]\npositions_stride = 10\nrepeats = 1\ncrlb_objects = ["A"]\n'
        'crlb_stride = 5\nfidelity = "draft"\n')


def _env() -> dict:
    return dict(os.environ, PYTHONPATH=str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", ""))


def _start(*argv: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "nlosplan", *argv], env=_env(), stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)


def _run(*argv: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "nlosplan", *argv], env=_env(), capture_output=True, text=True,
                          timeout=600)


def _children(pid: int) -> set[int]:
    """Every living descendant of ``pid`` (from /proc)."""
    parents = {}
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if fields[0] != "Z":
            parents[int(stat.parent.name)] = int(fields[1])
    out, frontier = set(), {pid}
    while frontier:
        frontier = {p for p, pp in parents.items() if pp in frontier} - out
        out |= frontier
    return out


def _alive(pids) -> set[int]:
    alive = set()
    for p in pids:
        try:
            state = Path(f"/proc/{p}/stat").read_text().rsplit(")", 1)[1].split()[0]
        except OSError:
            continue
        if state != "Z":
            alive.add(p)
    return alive


def _wait_for(predicate, seconds: float, what: str):
    t0 = time.monotonic()
    while time.monotonic() - t0 < seconds:
        value = predicate()
        if value:
            return value
        time.sleep(0.2)
    pytest.fail(f"timed out waiting for {what}")


def _kill(proc: subprocess.Popen) -> None:
    os.killpg(proc.pid, signal.SIGKILL)  # the command and everything in its session (its own group)
    proc.wait()


def _captures(store: Path) -> tuple[int, str]:
    """Number of captures and a SHA-1 over (key, histogram bytes), in key order."""
    db = sqlite3.connect(f"file:{store}?mode=ro", uri=True)
    try:
        rows = db.execute("SELECT key, data FROM captures ORDER BY key").fetchall()
    finally:
        db.close()
    h = hashlib.sha1()
    for key, data in rows:
        h.update(key.encode() + bytes(data))
    return len(rows), h.hexdigest()


def test_kill_9_of_dataset_build_then_resume_equals_an_uninterrupted_build(tmp_path):
    build = ["dataset", "build", "--objects", "A,S", "--sizes", "8in", "--positions", "0-9", "--repeats", "2",
             "--fidelity", "draft", "--batch", "5"]
    full, killed = tmp_path / "full.sqlite", tmp_path / "killed.sqlite"
    assert _run(*build, "--store", str(full)).returncode == 0
    proc = _start(*build, "--store", str(killed))

    def some_stored():
        try:
            return killed.exists() and _captures(killed)[0] >= 10
        except sqlite3.Error:  # the schema is being created
            return False

    _wait_for(some_stored, 300, "the first captures")
    _kill(proc)
    n_killed = _captures(killed)[0]
    assert 10 <= n_killed < 40, "the build ended before the kill: nothing was interrupted"
    resumed = _run(*build, "--store", str(killed), "--json")
    assert resumed.returncode == 0, resumed.stderr
    assert json.loads(resumed.stdout)["captures_skipped"] == n_killed
    assert _captures(killed) == _captures(full) and _captures(full)[0] == 40


def _design(out: Path, toml: Path, *extra: str) -> list[str]:
    return ["design", "--quick", "--config", str(toml), "--out", str(out), *extra]


def _evaluations(out: Path) -> list[tuple]:
    rows = [json.loads(line) for line in (out / "design_evaluations.jsonl").read_text().splitlines() if line.strip()]
    return sorted((r["evaluator"], r["task"], json.dumps(r["design"], sort_keys=True), r["seed"],
                   str(r.get("condition")), None if r["value"] != r["value"] else round(r["value"], 9)) for r in rows)


@pytest.fixture(scope="module")
def design_done(tmp_path_factory):
    """An uninterrupted serial run of the tiny configuration (its evaluations and references)."""
    d = tmp_path_factory.mktemp("design")
    (d / "tiny.toml").write_text(TINY)
    res = _run(*_design(d / "done", d / "tiny.toml", "--workers", "1"))
    assert res.returncode == 0, res.stderr
    return d


def test_kill_9_of_design_then_resume_gives_the_uninterrupted_evaluations(design_done, tmp_path):
    out = tmp_path / "killed"
    out.mkdir()
    shutil.copytree(design_done / "done" / "reference", out / "reference")  # same references, no simulation
    log = out / "design_evaluations.jsonl"
    proc = _start(*_design(out, design_done / "tiny.toml", "--workers", "1"))
    _wait_for(lambda: log.exists() and len(log.read_text().splitlines()) >= 8, 300, "eight evaluations")
    _kill(proc)
    resumed = _run(*_design(out, design_done / "tiny.toml", "--workers", "1", "--resume", "--json"))
    assert resumed.returncode == 0, resumed.stderr
    assert _evaluations(out) == _evaluations(design_done / "done")
    again = _run(*_design(out, design_done / "tiny.toml", "--workers", "1"))  # a rerun over it is refused
    assert again.returncode == 2 and "holds a previous run" in again.stderr
    assert _evaluations(out) == _evaluations(design_done / "done")


@pytest.mark.parametrize("executor", [["--workers", "2"], ["--cluster", "local:2"]], ids=["pool", "dask"])
def test_no_worker_outlives_a_killed_design(design_done, tmp_path, executor):
    out = tmp_path / "d"
    out.mkdir()
    shutil.copytree(design_done / "done" / "reference", out / "reference")
    log = out / "design_evaluations.jsonl"
    proc = _start(*_design(out, design_done / "tiny.toml", *executor))
    workers = _wait_for(lambda: len(_children(proc.pid)) >= 2 and log.exists() and log.stat().st_size > 0 and
                        _children(proc.pid), 300, "the workers at work")
    os.kill(proc.pid, signal.SIGKILL)  # the parent only: its workers must notice
    proc.wait()
    t0 = time.monotonic()
    while _alive(workers) and time.monotonic() - t0 < 10:
        time.sleep(0.2)
    left = _alive(workers)
    for p in left:  # do not leave them to the next test
        os.kill(p, signal.SIGKILL)
    assert not left, f"{len(left)} of {len(workers)} worker processes outlived the killed design by 10 s"
