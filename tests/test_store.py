"""`CaptureStore`: round trips, keys, filters, refusals, and a writer killed with SIGKILL."""

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.data.store import SCHEMA_VERSION, CaptureStore, capture_key, sensor_hash

S3 = preset("tmf8828-3x3-short")


def lab(**kw):
    out = dict(object="A", size="8in", position=3, lights="off", repeat=0, source="test", x=1.25, y=0.5)
    out.update(kw)
    return out


@pytest.fixture
def store(tmp_path):
    with CaptureStore(tmp_path / "s.sqlite") as st:
        yield st


def test_round_trip_is_bit_exact_with_labels_and_metadata(store):
    rng = np.random.default_rng(0)
    counts = rng.integers(0, 2**24, (3, 3, 128))  # up to the 24-bit register maximum
    mean = rng.random((3, 3, 128)).astype(np.float32) * 1e6
    i1 = store.put(counts, lab(), sensor=S3, meta={"gantry": {"commanded": [0.1, 0.2]}})
    i2 = store.put(mean, lab(object="circle", repeat=-1, x=None, y=None), sensor=S3)
    caps = {c.id: c for c in store.iter_captures()}
    assert caps[i1].histogram.dtype == np.int64 and np.array_equal(caps[i1].histogram, counts)
    assert caps[i2].histogram.dtype == np.float32 and np.array_equal(caps[i2].histogram, mean)
    assert caps[i1].meta["gantry"] == {"commanded": [0.1, 0.2]} and caps[i1].meta["created_utc"].endswith("+00:00")
    assert caps[i1].labels["class_group"] == "letters" and caps[i2].labels["class_group"] == "shapes"
    assert caps[i1].labels["zones"] == "3x3" and caps[i1].labels["sensor_hash"] == sensor_hash(S3)
    ds = store.load()
    assert ds.bin_width_ps == S3.bin_width_ps and ds.histograms.shape == (2, 3, 3, 128)
    # int64 counts up to 2**24 - 1 are exact in the Dataset's float32
    assert np.array_equal(ds.histograms[0].astype(np.int64), counts) and np.array_equal(ds.histograms[1], mean)
    row = ds.labels.iloc[0]
    assert [row[k] for k in ("object", "size", "position", "x", "y", "lights", "repeat")] == ["A", "8in", 3, 1.25, 0.5,
                                                                                              "off", 0]
    assert np.isnan(ds.labels.iloc[1].x) and store.sensor(sensor_hash(S3)) == S3


def test_duplicates_are_detected_and_put_many_skips_them(store):
    h = np.ones((3, 3, 128), np.int64)
    rid = store.put(h, lab(), sensor=S3)
    assert store.has(capture_key(lab(), S3)) and store.keys() == {capture_key(lab(), S3)}
    with pytest.raises(UserError, match="stored already"):
        store.put(h * 2, lab(), sensor=S3)
    res = store.put_many([(h, lab()), (h * 3, lab(repeat=1)), (h * 4, lab(repeat=2), {"note": "x"})], sensor=S3)
    assert res.ids[0] == rid and (res.added, res.skipped) == (2, 1) and store.count() == 3
    # the first capture was not replaced; the per-item metadata was stored
    first = next(store.iter_captures(id=rid))
    assert first.histogram.max() == 1
    assert next(store.iter_captures(repeat=2)).meta["note"] == "x"
    # a different seed or sensor is a different capture
    store.put(h, lab(seed=7), sensor=S3)
    store.put(h, lab(), sensor=S3.replace(jitter_fwhm_ps=100.0))
    assert store.count() == 5 and store.count(seed=7) == 1
    # the sensor's name is not part of its identity
    assert sensor_hash(S3.replace(name="renamed")) == sensor_hash(S3)


def test_load_filters_and_refuses_mixed_shapes_or_bin_widths(store):
    h3, h8 = np.zeros((3, 3, 128), np.int64), np.zeros((8, 8, 128), np.int64)
    for p in range(4):
        store.put(h3 + p, lab(position=p, lights="off"), sensor=S3)
        store.put(h3 + 10 + p, lab(position=p, lights="on"), sensor=S3)
    store.put(h8, lab(position=0), sensor=preset("tmf8828-8x8-short"))
    long3 = preset("tmf8828-3x3-long")
    store.put(h3, lab(position=9, source="long"), sensor=long3)
    off = store.load(lights="off", zones="3x3", source="test")
    assert len(off) == 4 and set(off.labels.lights) == {"off"}
    assert list(off.labels.position) == [0, 1, 2, 3] and list(off.histograms[:, 0, 0, 0]) == [0, 1, 2, 3]
    assert len(store.load(position=[1, 2], lights="on", zones="3x3")) == 2
    assert store.load(source="long").bin_width_ps == 260.0
    with pytest.raises(UserError, match="mix histogram shapes or bin widths") as e:
        store.load(lights="off")
    assert "\n" not in str(e.value)
    with pytest.raises(UserError, match="bin widths"):
        store.load(zones="3x3")
    with pytest.raises(UserError, match="no captures"):
        store.load(object="B")
    with pytest.raises(UserError, match="cannot filter captures by 'colour'"):
        store.count(colour="red")


def test_bad_captures_are_refused_with_one_line(store):
    h = np.zeros((3, 3, 128), np.int64)
    cases = [
        (np.zeros((3, 3, 64)), lab(), "does not match the sensor"),
        (h, lab(lights="dim"), "lights='dim'"),
        (h, {**lab(), "colour": "red"}, "unknown capture label"),
        (h, {k: v for k, v in lab().items() if k != "source"}, "miss source"),
        (h, lab(object="mug"), "give class_group"),
        (h, lab(zones="8x8"), "differ from the sensor"),
        (np.full((3, 3, 128), np.nan), lab(), "NaN"),
    ]
    for hist, labels, msg in cases:
        with pytest.raises(UserError, match=msg) as e:
            store.put(hist, labels, sensor=S3)
        assert "\n" not in str(e.value)
    store.put(h, lab(object="mug", class_group="other"), sensor=S3)
    assert store.count() == 1


def test_refuses_files_that_are_not_stores(tmp_path):
    text = tmp_path / "notes.sqlite"
    text.write_text("not a database, just text " * 100)
    with pytest.raises(UserError, match="not an nlosplan capture store"):
        CaptureStore(text)
    foreign = tmp_path / "foreign.sqlite"
    with sqlite3.connect(foreign) as db:
        db.execute("CREATE TABLE t (a)")
    with pytest.raises(UserError, match="not an nlosplan capture store"):
        CaptureStore(foreign)
    with sqlite3.connect(foreign) as db:  # untouched: still its own journal mode, its own table
        assert db.execute("PRAGMA journal_mode").fetchone()[0] == "delete"
    with pytest.raises(UserError, match="is a folder"):
        CaptureStore(tmp_path)
    with pytest.raises(UserError, match="does not exist"):
        CaptureStore(tmp_path / "missing.sqlite", create=False)
    newer = tmp_path / "newer.sqlite"
    CaptureStore(newer).close()
    with sqlite3.connect(newer) as db:
        db.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 1}")
    with pytest.raises(UserError, match="newer than this nlosplan"):
        CaptureStore(newer)


def test_store_is_wal_and_a_reader_sees_only_committed_captures(tmp_path):
    path = tmp_path / "s.sqlite"
    with CaptureStore(path) as writer, CaptureStore(path) as reader:
        assert writer._conn().execute("PRAGMA journal_mode").fetchone()[0] == "wal"
        writer.put(np.zeros((3, 3, 128), np.int64), lab(), sensor=S3)
        db = writer._conn()
        db.execute("BEGIN IMMEDIATE")  # a writer in the middle of a transaction
        db.execute("UPDATE captures SET object = 'B'")
        assert reader.count() == 1 and list(reader.load().labels.object) == ["A"]
        db.execute("ROLLBACK")


WRITER = r"""
import sys
import numpy as np
from nlosplan.sensor_models import preset
from nlosplan.data.store import CaptureStore, capture_key

path, n = sys.argv[1], int(sys.argv[2])
sensor = preset("tmf8828-3x3-short")
with CaptureStore(path) as st:
    stored = st.keys()
    for i in range(n):
        labels = dict(object="A", size="8in", position=i % 100, lights="off", repeat=i // 100, source="test:kill",
                      x=0.01 * i, y=-0.01 * i)
        if capture_key(labels, sensor) in stored:
            continue
        hist = np.random.default_rng(i).integers(0, 2**24, (3, 3, 128))
        st.put(hist, labels, sensor=sensor, meta={"i": i})
        print(i, flush=True)
"""


def _writer(path, n):
    return subprocess.Popen([sys.executable, "-c", WRITER, str(path), str(n)], stdout=subprocess.PIPE, text=True,
                            env={**os.environ, "JAX_PLATFORMS": "cpu"})


def _check_complete(path) -> list[int]:
    """Integrity, and every capture equal to what the writer meant to write; returns the capture indices."""
    with CaptureStore(path) as st:
        assert st.integrity_check() == "ok"
        seen = []
        for c in st.iter_captures():
            i = c.meta["i"]
            assert np.array_equal(c.histogram, np.random.default_rng(i).integers(0, 2**24, (3, 3, 128)))
            assert c.histogram.dtype == np.int64 and c.histogram.shape == (3, 3, 128)
            assert (c.labels["position"], c.labels["repeat"], c.labels["x"]) == (i % 100, i // 100, 0.01 * i)
            seen.append(i)
        assert st.count() == len(seen)
    return seen


def test_writer_killed_with_sigkill_leaves_a_sound_store_and_resumes(tmp_path):
    path = tmp_path / "kill.sqlite"
    proc = _writer(path, 100_000)
    printed = []
    with CaptureStore(path) as reader:  # reads while the writer commits
        while len(printed) < 8:
            line = proc.stdout.readline()
            assert line, "writer ended early"
            printed.append(int(line))
            reader.count()
        time.sleep(0.05)
        reader.load(source="test:kill")
    proc.send_signal(signal.SIGKILL)
    out, _ = proc.communicate()
    printed += [int(v) for v in out.split()]
    assert proc.returncode == -signal.SIGKILL
    seen = _check_complete(path)
    # the count is one of the committed counts: every printed commit, at most one commit not yet printed
    assert len(seen) in (len(printed), len(printed) + 1) and seen == list(range(len(seen)))
    # rerunning the writer adds only the missing captures
    n = len(seen) + 15
    rerun = _writer(path, n)
    out, _ = rerun.communicate(timeout=120)
    assert rerun.returncode == 0 and [int(v) for v in out.split()] == list(range(len(seen), n))
    assert _check_complete(path) == list(range(n))


def test_info_tables(store):
    h = np.zeros((3, 3, 128), np.int64)
    store.put_many([(h, lab(position=p, repeat=r)) for p in range(5) for r in range(3)], sensor=S3)
    table = store.summary()
    assert table.to_dict("records") == [dict(source="test", zones="3x3", lights="off", size="8in", objects=1,
                                             positions=5, repeats=3, captures=15)]
    sensors = store.sensors()
    assert list(sensors.captures) == [15] and json.loads(S3.to_json())["name"] == sensors.name[0]
