"""The stability catalog runs once per code version in design runs (nlosplan.planner.design.catalog)."""

import json

from nlosplan.planner.design import catalog
from nlosplan.cases import CaseResult


def _fake_run(calls):
    def run(cases):
        calls.append(len(cases))
        return [CaseResult("a", "", True, "", 0.1), CaseResult("b", "", False, "x", 0.2)]
    return run


def test_catalog_runs_once_per_code_version_and_is_marked_cached(tmp_path, monkeypatch):
    monkeypatch.setenv("NLOSPLAN_CACHE", str(tmp_path))
    calls, said = [], []
    monkeypatch.setattr("nlosplan.stability.run_cases", _fake_run(calls))
    first = catalog.stability_summary(False, True, said.append)
    assert first["cached"] is False and (first["passed"], first["total"], first["failed"]) == (1, 2, ["b"])
    assert said == ["stability: the catalog"] and len(calls) == 1 and calls[0] > 10
    again = catalog.stability_summary(False, True, said.append)
    assert again["cached"] is True and again["failed"] == ["b"] and len(calls) == 1
    # --no-cache runs it regardless; another code version is another entry
    catalog.stability_summary(False, False)
    assert len(calls) == 2
    monkeypatch.setattr(catalog.reference_cache, "code_version", lambda: "edited")
    assert catalog.stability_summary(False, True)["cached"] is False and len(calls) == 3


def test_a_damaged_entry_is_run_again_and_replaced(tmp_path, monkeypatch):
    monkeypatch.setenv("NLOSPLAN_CACHE", str(tmp_path))
    calls = []
    monkeypatch.setattr("nlosplan.stability.run_cases", _fake_run(calls))
    path = tmp_path / "stability" / f"{catalog.catalog_key()}.json"
    path.parent.mkdir(parents=True)
    path.write_text("{not json")
    assert catalog.stability_summary(False, True)["cached"] is False and len(calls) == 1
    assert json.loads(path.read_text())["total"] == 2


def test_quick_runs_do_not_run_it(tmp_path, monkeypatch):
    monkeypatch.setenv("NLOSPLAN_CACHE", str(tmp_path))
    assert catalog.stability_summary(True) == {"ran": False, "note": "not run with --quick; run `nlosplan check`"}
    assert not (tmp_path / "stability").exists()
