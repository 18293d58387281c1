"""The rig page's reading of a capture store while a run writes it (no browser): what ``rig capture`` on the
emulators stored, read back read-only and incrementally, against the store's own API; an archived store."""

import json
import sqlite3

import numpy as np
import pytest

from nlosplan.cli import main
from nlosplan.data.store import CaptureStore
from nlosplan.denali.geometry import grid_mm
from nlosplan.reports.live import rig_watch
from nlosplan.reports.live.rig_page import status_html
from nlosplan.reports.live.rig_watch import RigWatch, is_store, open_readonly

ARGS = ["rig", "capture", "--emulate", "--repeats", "2", "--settle", "0", "--time-scale", "50", "--json"]


@pytest.fixture(scope="module")
def captured(tmp_path_factory):
    """Two runs in one store: positions 0-2 with a garbled sensor link, then positions 10-11."""
    tmp = tmp_path_factory.mktemp("rig")
    db = tmp / "runs.db"
    for extra in (["--positions", "0-2", "--emulate-faults", "garble=40"], ["--positions", "10-11"]):
        assert main(ARGS + extra + ["--store", str(db)]) == 0
    return db


def test_a_run_is_read_back_as_the_store_holds_it(captured, capsys):
    capsys.readouterr()
    watch = RigWatch(captured, min_interval_s=0)
    watch.refresh(force=True)
    with CaptureStore(captured) as st:
        caps = list(st.iter_captures())
    runs = list(dict.fromkeys(c.meta["run_id"] for c in caps))
    assert list(watch.runs) == runs and watch.run_id == runs[-1]     # the newest run is shown
    watch.fixed_run = runs[0]
    first = [c for c in caps if c.meta["run_id"] == runs[0]]
    c = watch.counts()
    assert (c["captures"], c["positions"], c["repeats"], c["planned"], c["left"]) == (6, 3, 2, 6, 0)
    got = sorted((p["x_mm"], p["y_mm"]) for p in watch.captured_positions())
    assert np.allclose(got, sorted(tuple(grid_mm(i)) for i in range(3)), atol=1e-3)
    assert watch.current_position() == pytest.approx(first[-1].meta["reported_mm"])
    assert watch.limits_mm() == ((0.0, 320.0), (0.0, 320.0))
    f = watch.faults()
    asm = first[-1].meta["frame"]["assembler"]
    assert f["garbage_lines"] == asm["garbage_lines"] > 0 and f["dropped_frames"] == asm["dropped_frames"]
    assert f["retries"] == first[-1].meta["run_faults"]["retries"]
    watch._read_hist(first[-1].id)
    np.testing.assert_array_equal(watch.last_hist["counts"], first[-1].histogram)
    html = status_html(watch)
    assert f"<span data-k='run'>{runs[0]}</span>" in html and "<b data-k='captures'>6</b>" in html
    assert "<b data-k='planned'>6</b> captures" in html and "(read-only: archived)" not in html


def test_only_new_captures_are_read(captured, tmp_path):
    import shutil

    db = tmp_path / "copy.db"
    with CaptureStore(captured) as st:   # a consistent copy (the WAL merged)
        st._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    shutil.copy(captured, db)
    watch = RigWatch(db, min_interval_s=0)
    watch.refresh(force=True)
    n = sum(len(v) for v in watch.runs.values())
    seen_ids = []
    real = watch._db

    class Spy:
        def execute(self, sql, params=()):
            if "id > ?" in sql:
                seen_ids.append(params[0])
            return real.execute(sql, params)

    watch._db = Spy()
    assert not watch.refresh(force=True)                 # nothing new
    with CaptureStore(db) as st:
        last = next(st.iter_captures(id=int(st.labels()["id"].max())))
        st.put(last.histogram, {**{k: last.labels[k] for k in ("object", "size", "position", "lights", "source")},
                                "repeat": 5, "capture_id": f"{last.meta['run_id']}/000099"},
               sensor=st.sensor(last.labels["sensor_hash"]),
               meta={"run_id": last.meta["run_id"], "step": 99, "commanded_mm": [1.0, 2.0],
                     "reported_mm": [1.0, 2.0]})
    assert watch.refresh(force=True)
    assert seen_ids == [n, n]                            # both reads asked only for ids after the last seen
    assert sum(len(v) for v in watch.runs.values()) == n + 1 and watch.current_position() == (1.0, 2.0)


def test_an_archived_store_is_read_only(captured, tmp_path, monkeypatch):
    import shutil

    arch = tmp_path / "archive"
    arch.mkdir()
    with CaptureStore(captured) as st:
        st._db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
    shutil.copy(captured, arch / "runs.db")
    monkeypatch.setattr(rig_watch, "writable", lambda p: False)   # as on a read-only medium (root can write anything)
    assert is_store(arch / "runs.db") and not is_store(tmp_path)
    con = open_readonly(arch / "runs.db")
    with pytest.raises(sqlite3.OperationalError, match="readonly|read-only"):
        con.execute("DELETE FROM captures")
    watch = RigWatch(arch / "runs.db", min_interval_s=0)
    watch.refresh(force=True)
    assert not watch.writable and "(read-only: archived)" in status_html(watch)
    assert sorted(p.name for p in arch.iterdir()) == ["runs.db"]   # immutable: no -wal/-shm created
    from nlosplan.reports.live.server import Page, _session_allowed

    page = Page("rig", arch / "runs.db", planner_dir=tmp_path, actions=True, token=None)
    assert _session_allowed(None, page, watch) == (False, "the store is archived (read-only): no actions")


@pytest.mark.skipif(__import__("os").geteuid() == 0, reason="root may write any file: permissions cannot archive")
def test_permissions_make_a_store_archived(captured, tmp_path):
    import os
    import shutil

    arch = tmp_path / "a"
    arch.mkdir()
    shutil.copy(captured, arch / "runs.db")
    os.chmod(arch / "runs.db", 0o444)
    os.chmod(arch, 0o555)
    try:
        assert not rig_watch.writable(arch / "runs.db")
    finally:
        os.chmod(arch, 0o755)


def test_a_store_that_does_not_exist_yet_is_waited_for(tmp_path):
    watch = RigWatch(tmp_path / "later.db", min_interval_s=0)
    assert not watch.refresh(force=True) and not watch.opened
    assert "waiting for the run to create the store" in status_html(watch)
    json.dumps(watch.summary())


def test_a_run_not_started_yet_in_a_store_of_other_runs(captured):
    watch = RigWatch(captured, run_id="plan-next", min_interval_s=0)   # what --live asks before the first capture
    assert watch.refresh(force=True) and len(watch.runs) == 2
    assert watch.last_hist is None and watch.counts()["captures"] == 0
    assert "<span data-k='run'>plan-next</span>: no capture yet" in status_html(watch)
