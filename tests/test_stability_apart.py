"""The stability catalog runs in a process of its own whose XLA compiles cheaply (nlosplan.stability.run_apart)."""

import pytest

from nlosplan.planner.design import catalog
from nlosplan.stability import CATALOG_XLA_FLAGS, all_cases, catalog_env, run_apart, run_cases


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
