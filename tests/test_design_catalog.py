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
    monkeypatch.setattr("nlosplan.stability.run_apart", _fake_run(calls))
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
    monkeypatch.setattr("nlosplan.stability.run_apart", _fake_run(calls))
    path = tmp_path / "stability" / f"{catalog.catalog_key()}.json"
    path.parent.mkdir(parents=True)
    path.write_text("{not json")
    assert catalog.stability_summary(False, True)["cached"] is False and len(calls) == 1
    assert json.loads(path.read_text())["total"] == 2


def test_quick_runs_do_not_run_it(tmp_path, monkeypatch):
    monkeypatch.setenv("NLOSPLAN_CACHE", str(tmp_path))
    assert catalog.stability_summary(True) == {"ran": False, "note": "not run with --quick; run `nlosplan check`"}
    assert not (tmp_path / "stability").exists()


def test_the_catalog_runs_beside_the_references_largest_first(tmp_path, monkeypatch):
    """A design run's catalog is one more executor job, after the largest reference; its summary is kept."""
    from nlosplan.planner.design import run
    from nlosplan.planner.design.data import SceneSet
    from nlosplan.planner.design.executors import SerialExecutor
    from nlosplan.planner.design.jobs import ReferenceJob
    from nlosplan.sensor_models.presets import preset

    monkeypatch.setenv("NLOSPLAN_CACHE", str(tmp_path / "cache"))
    calls, order = [], []
    monkeypatch.setattr("nlosplan.stability.run_apart", _fake_run(calls))

    def fake_reference(job):
        order.append(job.label)
        return {"path": job.path, "status": "ok", "seconds": 1.0, "scenes": 1, "label": job.label}

    real_catalog = run.run_catalog

    def catalog_job(job):
        order.append(job.label)
        return real_catalog(job)

    monkeypatch.setattr(run, "build_reference", fake_reference)
    monkeypatch.setattr(run, "run_catalog", catalog_job)
    scenes = SceneSet(objects=("A",), positions=(0,), repeats=1, crlb_objects=(), fidelity="draft")
    base = preset("tmf8828-3x3-short")
    jobs = [ReferenceJob(str(tmp_path / f"{r}x{r}.npz"), base.replace(zones_rows=r, zones_cols=r), scenes, f"{r}x{r}")
            for r in (1, 3, 2)]
    said = []
    seconds, summary = run._simulate(SerialExecutor(), jobs, lambda text, *a: said.append((text, a)), "references",
                                     cache=False, catalog=True)
    assert order == ["3x3", "stability catalog", "2x2", "1x1"]
    assert seconds == {"3x3": 1.0, "2x2": 1.0, "1x1": 1.0}
    assert summary["cached"] is False and (summary["passed"], summary["total"], summary["failed"]) == (1, 2, ["b"])
    assert said[1] == ("references: stability catalog", (2, 4)) and len(calls) == 1
    # cache=False keeps nothing; with the cache the summary is kept for the next run
    assert catalog.kept_summary(False, True) is None
    run._simulate(SerialExecutor(), jobs[:1], lambda *a: None, "references", cache=False, catalog=False)
    assert len(calls) == 1
    assert catalog.keep(summary, True)["cached"] is False
    assert catalog.kept_summary(False, True)["cached"] is True
    # nothing to simulate: the catalog is not run there (the run does it at the end)
    assert run._simulate(SerialExecutor(), [], lambda *a: None, "references", cache=False, catalog=True) == ({}, None)
    assert len(calls) == 1


def test_a_catalog_job_that_dies_is_said_and_left_to_the_end(tmp_path, monkeypatch):
    from nlosplan.planner.design import run
    from nlosplan.planner.design.data import SceneSet
    from nlosplan.planner.design.executors import SerialExecutor
    from nlosplan.planner.design.jobs import ReferenceJob
    from nlosplan.sensor_models.presets import preset

    monkeypatch.setenv("NLOSPLAN_CACHE", str(tmp_path / "cache"))
    monkeypatch.setattr(run, "build_reference", lambda job: {"status": "ok", "seconds": 2.0})

    def dies(job):
        raise MemoryError("worker killed")

    monkeypatch.setattr(run, "run_catalog", dies)
    scenes = SceneSet(objects=("A",), positions=(0,), repeats=1, crlb_objects=(), fidelity="draft")
    job = ReferenceJob(str(tmp_path / "1x1.npz"), preset("tmf8828-3x3-short"), scenes, "3x3")
    said = []
    seconds, summary = run._simulate(SerialExecutor(), [job], lambda text, *a: said.append(text), "references",
                                     cache=False, catalog=True)
    assert summary is None and seconds == {"3x3": 2.0}
    assert any("stability catalog stopped on its worker (MemoryError: worker killed); it runs again at the end" in s
               for s in said), said
