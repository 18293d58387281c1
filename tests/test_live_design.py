"""The design page's reading of a run's files (no browser): progress by the search's own rule, the log read
incrementally (torn lines too), the answer so far, and result.json once written.

The run is replayed without computing anything: the search rebuilt from the checkpoint suggests its jobs, and
each gets a made-up metric (``fake_result``), appended to the log as the run appends its results."""

import json
import math
import time

import pytest

from nlosplan.planner.design.progress import design_progress, search_from_files
from nlosplan.planner.design.requirements import METRIC_OF_TASK
from nlosplan.planner.design.run import CHECKPOINT, EVALUATIONS, DesignConfig
from nlosplan.planner.design.search import SearchConfig
from nlosplan.planner.design.space import DesignSpace
from nlosplan.planner.design.data import SceneSet
from nlosplan.reports.live.design_page import answer_rows, status_html
from nlosplan.reports.live.design_watch import DesignWatch, is_design_folder


def config() -> DesignConfig:
    return DesignConfig(space=DesignSpace(zones=((1, 1), (3, 3)), bin_factors=(1, 2),
                                          axes=("zones", "jitter_fwhm_ps")),
                        search=SearchConfig(grid_points=3, refine_steps=1, seeds=1, candidates=1, optimize_evals=4),
                        scenes=SceneSet(objects=("A", "S"), positions=(0, 50), crlb_objects=("A",)), label="quick")


def fake_result(job, k: int) -> dict:
    """A made-up metric: worse with jitter and with one zone; the run time grows with k."""
    d = job.design
    worse = d.jitter_fwhm_ps / 1000.0 + (0.5 if d.n_zones == 1 else 0.0)
    v = 0.02 * (1 + worse) if job.task == "loc" else {"shape": 0.6, "size": 0.95}[job.task] * (1 - 0.3 * worse)
    return {**job.to_dict(), "metric": METRIC_OF_TASK[job.task][0], "value": v, "lo": 0.9 * v, "hi": 1.1 * v,
            "seconds": 0.01 * (k + 1), "status": "ok", "reason": "", "extra": {}}


@pytest.fixture
def out(tmp_path):
    cfg = config()
    (tmp_path / CHECKPOINT).write_text(json.dumps({"config_hash": cfg.hash(), "config": cfg.to_dict(),
                                                   "candidates": None, "optimize_log": []}))
    (tmp_path / EVALUATIONS).write_text("")
    return tmp_path


def test_progress_follows_the_search_through_its_stages(out):
    watch = DesignWatch(out, min_interval_s=0)
    watch.refresh(force=True)
    assert is_design_folder(out)
    assert watch.progress["stage"] == "references" and watch.progress["done"] == 0   # references not simulated yet
    search, _, references = search_from_files(out)
    for path in references.values():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"")   # the names only: the search never reads them
    watch.refresh(force=True)
    p = watch.progress
    assert p["stage"] == "screen" and p["left"] > 0 and set(p["left_by_evaluator"]) == {"bound"}
    stages, k = [], 0
    with open(out / EVALUATIONS, "a") as fh:
        while True:
            search = search_from_files(out, watch.results).search
            jobs = search.suggest()
            if not jobs:
                break
            before = watch.progress
            assert before["stage"] == search.stage and before["left"] == len(jobs)
            fh.write(json.dumps(fake_result(jobs[0], k)) + "\n")
            fh.flush()
            k += 1
            assert watch.refresh(force=True)
            assert watch.progress["done"] == k
            if watch.progress["stage"] == before["stage"] == "screen":   # a fixed job list
                assert watch.progress["left"] == before["left"] - 1
            elif watch.progress["stage"] == before["stage"] == "curves":   # seeds are added while a verdict is open
                assert watch.progress["left"] <= before["left"]
            stages.append(watch.progress["stage"])
    assert stages[0] == "screen" and "curves" in stages
    assert watch.progress["stage"] == "optimize" and watch.progress["left"] == 0   # COBYLA runs next: no evaluations
    assert watch.progress["failed"] == 0 and len(watch.progress["costs"]) > 3
    cheapest, params = answer_rows(watch.answer())
    assert [r["requirement"] for r in cheapest] == [r.name for r in config().requirements]
    met = [r for r in cheapest if r.get("key")]
    assert met and all(r["metric [interval]"].startswith(f"{r['value']:.4g} [") for r in met)
    assert {(r["task"], r["parameter"]) for r in params} == {(t, a) for t in ("loc", "shape", "size")
                                                             for a in ("zones", "jitter_fwhm_ps")}
    html = status_html(watch)
    assert f"<b data-k='done'>{k}</b>" in html and "<b data-k='stage'>optimize</b>" in html


def test_the_log_is_read_incrementally_and_a_torn_line_waits(out):
    search, _, references = search_from_files(out)
    for path in references.values():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"")
    jobs = search.suggest()
    lines = [json.dumps(fake_result(j, i)) for i, j in enumerate(jobs[:3])]
    watch = DesignWatch(out, min_interval_s=0)
    with open(out / EVALUATIONS, "a") as fh:
        fh.write(lines[0] + "\n" + lines[1][:20])   # the second line is being written
    watch.refresh(force=True)
    assert len(watch.results) == 1
    with open(out / EVALUATIONS, "a") as fh:
        fh.write(lines[1][20:] + "\n" + '{"torn by a kill": \n' + lines[2] + "\n")
    watch.refresh(force=True)
    assert [r["key"] for r in watch.results] == [j.key for j in jobs[:3]]
    assert watch.progress["done"] == 3 == design_progress(out)["done"]
    assert not watch.refresh()           # within the interval: nothing read
    (out / EVALUATIONS).replace(out / (EVALUATIONS + ".bak"))   # a new run over the folder starts a new log
    (out / EVALUATIONS).write_text(lines[0] + "\n")
    watch.refresh(force=True)
    assert len(watch.results) == 1


def test_time_left_uses_the_evaluations_seen_landing(out, monkeypatch):
    search, _, references = search_from_files(out)
    for path in references.values():
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_bytes(b"")
    jobs = search.suggest()
    clock = [1000.0]
    monkeypatch.setattr("nlosplan.reports.live.design_watch.time.monotonic", lambda: clock[0])
    watch = DesignWatch(out, min_interval_s=0)
    watch.refresh(force=True)
    assert watch.seconds_left() is None            # nothing has landed while the page looked
    with open(out / EVALUATIONS, "a") as fh:
        for i, j in enumerate(jobs[:4]):
            r = fake_result(j, 0)
            r["seconds"] = 2.0
            fh.write(json.dumps(r) + "\n")
            fh.flush()
            clock[0] += 1.0                        # 2 s of evaluation per wall second: two workers busy
            watch.refresh(force=True)
    left = watch.progress["left"]
    assert left == len(jobs) - 4
    assert watch.seconds_left() == pytest.approx(left * 2.0 / 2.0)


def test_result_json_is_the_answer_once_written(out):
    watch = DesignWatch(out, min_interval_s=0)
    time.sleep(0.01)
    final = {"cheapest": [{"requirement": "loc loc_rms_distance <= 0.05 m", "task": "loc", "verdict": "met",
                           "key": "3x3/b1x128/j0/p0/n1", "design": {"zones": "3x3"}, "cost": 1.5, "value": 0.031,
                           "lo": 0.029, "hi": 0.034, "world": "sim"}],
             "requirements": [{"task": "loc", "parameter": "zones", "minimum": 4.0, "interval": [2.0, 9.0]}]}
    (out / "result.json").write_text(json.dumps(final))
    watch.refresh(force=True)
    cheapest, params = answer_rows(watch.answer())
    assert cheapest == [{"requirement": "loc loc_rms_distance <= 0.05 m", "task": "loc", "verdict": "met",
                         "key": "3x3/b1x128/j0/p0/n1", "cost": 1.5, "value": 0.031, "lo": 0.029, "hi": 0.034,
                         "world": "sim", "metric [interval]": "0.031 [0.029, 0.034]"}]   # whatever fields they carry
    assert params == final["requirements"]
    from nlosplan.reports.live.html import table

    html = table(cheapest, name="cheapest")
    assert '<td data-col="verdict" title="met">met</td>' in html and "data-col=\"world\"" in html
    assert math.isfinite(watch.seconds_since_last())
