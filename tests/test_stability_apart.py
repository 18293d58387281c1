"""The stability catalog runs in a process of its own whose XLA compiles cheaply (nlosplan.stability.run_apart)."""

import os

import pytest

from nlosplan.planner.design import catalog
from nlosplan.stability import CATALOG_XLA_FLAGS, PARENT_ENV, all_cases, catalog_env, run_apart, run_cases


def _cases(*names):
    known = {c.name: c for c in all_cases()}
    return [known[n] for n in names]


def test_cases_run_apart_give_what_they_give_here_with_progress_per_case():
    cases = _cases("bins-1", "reject-zero-bins")
    seen = []
    apart = run_apart(cases, seen.append)
    here = run_cases(cases)
    assert [r.name for r in apart] == [r.name for r in seen] == ["bins-1", "reject-zero-bins"]
    assert [r.passed for r in apart] == [r.passed for r in here] == [True, True]
    assert apart[1].detail == here[1].detail and "UserError" in apart[1].detail
    assert all(r.seconds > 0 for r in apart)


def test_the_catalogs_xla_options_come_after_the_users():
    env = catalog_env({"XLA_FLAGS": "--xla_force_host_platform_device_count=2", "HOME": "/h"})
    assert env["XLA_FLAGS"].split() == ["--xla_force_host_platform_device_count=2", *CATALOG_XLA_FLAGS]
    assert env["HOME"] == "/h"
    assert catalog_env({})["XLA_FLAGS"].split() == list(CATALOG_XLA_FLAGS)
    assert catalog_env({})[PARENT_ENV] == str(os.getpid())   # the child checks this pid, not its parent at import


def test_a_process_that_stops_early_is_an_error_naming_its_last_words():
    from nlosplan.cases import Case

    with pytest.raises(RuntimeError, match=r"stopped \(exit 2\) after 0 of 1 cases: no such stability case: nope$"):
        run_apart([Case("nope", "", lambda: (True, ""))])


def test_a_design_runs_summary_says_so_when_the_catalog_did_not_finish(tmp_path, monkeypatch):
    monkeypatch.setenv("NLOSPLAN_CACHE", str(tmp_path))

    def dies(cases, progress=None):
        raise RuntimeError("the stability catalog's process stopped (exit -9) after 3 of 51 cases: Killed")

    monkeypatch.setattr("nlosplan.stability.run_apart", dies)
    summary = catalog.stability_summary(False, True)
    assert summary == {"ran": False, "note": "did not finish: the stability catalog's process stopped (exit -9) after "
                                             "3 of 51 cases: Killed; run `nlosplan check`"}
    assert not (tmp_path / "stability").exists()  # nothing kept: the next run tries again


@pytest.mark.parametrize("after_s", [0.0, 1.0], ids=["during-its-imports", "while-it-computes"])
def test_the_catalogs_process_ends_with_the_process_that_started_it(tmp_path, after_s):
    """A design worker that ends (or is killed) does not leave the catalog running for a minute, also when it dies
    before the catalog's process has imported anything (it is re-parented before it can watch)."""
    import contextlib
    import os
    import signal
    import subprocess
    import sys
    import time

    pidfile = tmp_path / "child.pid"
    starter = (
        "import subprocess, sys\n"
        "from nlosplan.stability import catalog_env\n"
        "p = subprocess.Popen([sys.executable, '-c', 'from nlosplan.stability import _child; _child()',"
        " 'gradients-transport'], env=catalog_env(), stdout=subprocess.DEVNULL)\n"
        f"open({str(pidfile)!r}, 'w').write(str(p.pid))\n"
        "p.wait()\n")
    parent = subprocess.Popen([sys.executable, "-c", starter])
    deadline = time.monotonic() + 60
    while not (pidfile.exists() and pidfile.read_text()) and time.monotonic() < deadline:
        time.sleep(0.1)
    child = int(pidfile.read_text())
    time.sleep(after_s)  # 0: the child is still importing; 1: importing or compiling the case that takes ~20 s
    os.kill(parent.pid, signal.SIGKILL)
    parent.wait()
    deadline = time.monotonic() + 10
    while time.monotonic() < deadline:
        try:
            os.kill(child, 0)
        except ProcessLookupError:
            break
        with contextlib.suppress(ChildProcessError):  # reap it if it became ours (re-parented to a subreaper)
            os.waitpid(child, os.WNOHANG)
        time.sleep(0.1)
    else:
        os.kill(child, signal.SIGKILL)
        raise AssertionError("the catalog's process outlived the process that started it by 10 s")


def test_check_says_in_one_line_when_the_cases_process_dies(capsys, monkeypatch):
    from nlosplan.cli import main

    def dies(cases, progress=None):
        raise RuntimeError("the stability catalog's process stopped (exit -9) after 3 of 51 cases: Killed")

    monkeypatch.setattr("nlosplan.stability.run_apart", dies)
    assert main(["check"]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert err[-1] == "nlosplan check: the stability catalog's process stopped (exit -9) after 3 of 51 cases: Killed"


def test_an_interrupted_caller_stops_the_cases_process(monkeypatch):
    import subprocess

    started = []

    class Recorded(subprocess.Popen):
        def __init__(self, *a, **k):
            super().__init__(*a, **k)
            started.append(self)

    monkeypatch.setattr(subprocess, "Popen", Recorded)
    seen = []

    def stop(res):
        seen.append(res)
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        run_apart(_cases("bins-1", "gradients-transport"), stop)  # the second case would run ~20 s
    assert [r.name for r in seen] == ["bins-1"] and len(started) == 1
    assert started[0].wait(timeout=5) != 0  # killed, not left to finish
