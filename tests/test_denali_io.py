"""The DENALI folder layout: import (labels, skips, refusals, resume) and export round trips, on a fake tree."""

import json
import pickle

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.sensor_models import preset
from nlosplan.denali import positions_xy
from nlosplan.data.denali_io import export_denali, import_denali, load_positions
from nlosplan.data.store import CaptureStore

FOLDERS = {  # folder -> (zones, object, size, class group, lights)
    "A_4inch_3x3_lightoff_NLOSdata": (3, "A", "4in", "letters", "off"),
    "halfcircle_8inch_3x3_lighton_NLOSdata": (3, "semicircle", "8in", "shapes", "on"),
    "i_4inch_8x8_lightoff_NLOSdata": (8, "I", "4in", "letters", "off"),
    "NOOBJECT_8inch_3x3_lightoff_NLOSdata": (3, "NOOBJECT", "8in", "background", "off"),
}
POSITIONS = (0, 5, 17)


def _data(folder: str, p: int) -> np.ndarray:
    n = FOLDERS[folder][0]
    seed = sorted(FOLDERS).index(folder) * 1000 + p
    return np.random.default_rng(seed).integers(0, 2**20, (3, n, n, 128))


@pytest.fixture
def tree(tmp_path):
    root = tmp_path / "denali-data"
    for folder in FOLDERS:
        d = root / folder / "spad_histogram"
        d.mkdir(parents=True)
        for p in POSITIONS:
            np.save(d / f"{p:03d}.npy", _data(folder, p))
        (root / folder / "tracking_rgb").mkdir()
    d = root / "italicA_8inch_3x3_lightoff_NLOSdata" / "spad_histogram"
    d.mkdir(parents=True)
    np.save(d / "000.npy", np.zeros((3, 3, 3, 128), np.int64))
    (root / "saved_dataset").mkdir()
    (root / "A_NLOSdata.pkl").write_bytes(b"never opened")
    (root / "A_4inch_3x3_lightoff_NLOSdata" / "spad_histogram" / "notes.txt").write_text("x")
    np.save(root / "A_4inch_3x3_lightoff_NLOSdata" / "spad_histogram" / "150.npy", np.zeros((3, 3, 3, 128)))
    return root


def test_import_labels_histograms_and_skips(tree, tmp_path):
    with CaptureStore(tmp_path / "s.sqlite") as st:
        res = import_denali(tree, st)
        assert (res["folders"], res["files"], res["captures_added"]) == (4, 12, 36)
        reasons = {s["path"]: s["reason"] for s in res["skipped"]}
        assert "unknown object 'italicA'" in reasons["italicA_8inch_3x3_lightoff_NLOSdata"]
        assert "not <object>_" in reasons["saved_dataset"]
        assert reasons["A_NLOSdata.pkl"] == "pickle file outside the folder layout; not opened"
        assert "not a capture file" in reasons["A_4inch_3x3_lightoff_NLOSdata/spad_histogram/notes.txt"]
        assert "capture number 150 has no position" in reasons["A_4inch_3x3_lightoff_NLOSdata/spad_histogram/150.npy"]
        xy = positions_xy()
        for c in st.iter_captures():
            folder = c.meta["folder"]
            zones, obj, size, group, lights = FOLDERS[folder]
            lab = c.labels
            assert (lab["object"], lab["size"], lab["class_group"], lab["lights"]) == (obj, size, group, lights)
            assert lab["zones"] == f"{zones}x{zones}" and lab["source"] == "real:denali" and lab["seed"] is None
            assert (lab["x"], lab["y"]) == tuple(xy[lab["position"]])
            assert c.histogram.dtype == np.int64
            assert np.array_equal(c.histogram, _data(folder, lab["position"])[lab["repeat"]])
        ds = st.load(zones="8x8")
        assert ds.bin_width_ps == preset("tmf8828-8x8-short").bin_width_ps and ds.histograms.shape == (9, 8, 8, 128)
        assert len(st.load(lights="off", zones="3x3")) == 18


def test_import_resumes_and_adds_only_new_files(tree, tmp_path):
    with CaptureStore(tmp_path / "s.sqlite") as st:
        import_denali(tree, st)
        again = import_denali(tree, st)
        assert (again["captures_added"], again["files"], again["files_stored_already"]) == (0, 0, 12)
        new = tree / "A_4inch_3x3_lightoff_NLOSdata" / "spad_histogram" / "042.npy"
        np.save(new, np.ones((2, 3, 3, 128), np.int32))
        more = import_denali(tree, st)
        assert (more["captures_added"], more["files"]) == (2, 1) and st.count() == 38
        assert st.count(position=42, repeat=[0, 1]) == 2


def test_positions_json_and_sensor_override(tree, tmp_path):
    pos = tmp_path / "tag1_positions.json"
    pos.write_text(json.dumps({f"frame{p}_tag1": [p * 0.1, -p * 0.2, 0.35] for p in range(20)} | {"note": "x"}))
    assert load_positions(pos)[17] == (17 * 0.1, -17 * 0.2)
    sensor8 = preset("tmf8828-8x8-short").replace(bin_width_ps=100.0)
    with CaptureStore(tmp_path / "s.sqlite") as st:
        import_denali(tree, st, positions_json=pos, sensors=[sensor8])
        lab = st.labels(position=5)
        assert set(lab.x) == {0.5} and set(lab.y) == {-1.0}
        assert st.load(zones="8x8").bin_width_ps == 100.0 and st.load(zones="3x3").bin_width_ps == pytest.approx(92.816)
    pos.write_text("[1, 2]")
    with pytest.raises(UserError, match="not a tag1_positions.json"):
        load_positions(pos)


def test_pickles_are_refused_unless_trusted(tree, tmp_path):
    d = tree / "A_4inch_3x3_lightoff_NLOSdata" / "spad_histogram"
    obj = np.empty((1, 3, 3, 128), dtype=object)
    obj[...] = 7
    np.save(d / "042.npy", obj, allow_pickle=True)
    with CaptureStore(tmp_path / "s.sqlite") as st:
        with pytest.raises(UserError, match="042.npy: refusing to load a file that needs pickle") as e:
            import_denali(tree, st)
        assert "may run code when loaded" in str(e.value) and "--trust-pickle" in str(e.value)
        assert "\n" not in str(e.value)
        (d / "042.npy").unlink()
        with open(d / "043.pkl", "wb") as f:
            pickle.dump(np.full((2, 3, 3, 128), 9), f)
        with pytest.raises(UserError, match="043.pkl: refusing .*may run code"):
            import_denali(tree, st)
        np.save(d / "042.npy", obj, allow_pickle=True)
        res = import_denali(tree, st, trust_pickle=True)
        assert res["captures_added"] == 36 + 1 + 2
        assert next(st.iter_captures(position=42)).histogram.max() == 7
        assert next(st.iter_captures(position=43, repeat=1)).histogram.min() == 9


def _counts(value, dtype=np.float64):
    a = np.full((1, 3, 3, 128), 5, dtype)
    a[0, 1, 2, 7] = value
    return a


@pytest.mark.parametrize("content, msg", [
    (b"\x93NUMPY garbage", "042.npy: not a readable .npy file"),
    (np.zeros((3, 3, 128), np.int64), r"042.npy: histogram shape \(3, 3, 128\), expected \(repeats, 3, 3, 128\)"),
    (-np.ones((1, 3, 3, 128), np.int64), r"042.npy: count -1 at index \[0, 0, 0, 0\] is negative \(1152 such"),
    # a float of 1e30 used to wrap to -9223372036854775808 in int64
    (_counts(1e30), r"count 1e\+30 at index \[0, 1, 2, 7\] is above the sensor's 24-bit range \(at most 16777215\)"),
    (_counts(2**24, np.int64), r"count 16777216 at index \[0, 1, 2, 7\] is above the sensor's 24-bit range"),
    (_counts(2.5), r"count 2.5 at index \[0, 1, 2, 7\] is not a whole number of counts"),
    (_counts(np.nan), r"count nan at index \[0, 1, 2, 7\] is not a finite number"),
    (_counts(-np.inf), r"count -inf at index \[0, 1, 2, 7\] is not a finite number"),
    (np.full((1, 3, 3, 128), True), "dtype bool are not counts"),
])
def test_bad_files_name_the_file_and_nothing_is_imported(tree, tmp_path, content, msg):
    path = tree / "A_4inch_3x3_lightoff_NLOSdata" / "spad_histogram" / "042.npy"
    if isinstance(content, np.ndarray):
        np.save(path, content)
    else:
        path.write_bytes(content)
    store = tmp_path / "s.sqlite"
    with pytest.raises(UserError, match=msg) as e:
        import_denali(tree, store)
    assert "\n" not in str(e.value)
    assert not store.exists()  # checked before the store is created: no partial import
    with pytest.raises(UserError, match="does not exist or is not a folder"):
        import_denali(tmp_path / "nowhere", None)


def test_whole_float_counts_within_precision_are_integers(tree, tmp_path):
    path = tree / "A_4inch_3x3_lightoff_NLOSdata" / "spad_histogram" / "042.npy"
    np.save(path, _counts(2**24 - 1 + 1e-9))  # float64 rounding of a whole count
    with CaptureStore(tmp_path / "s.sqlite") as st:
        import_denali(tree, st)
        hist = next(st.iter_captures(position=42)).histogram
    assert hist.dtype == np.int64 and hist[1, 2, 7] == 2**24 - 1 and hist[0, 0, 0] == 5


def test_an_empty_import_creates_no_store(tmp_path):
    (tmp_path / "data" / "README_folder").mkdir(parents=True)
    store = tmp_path / "s.sqlite"
    with pytest.raises(UserError, match=r"no capture files to import in .*1 entries skipped, e.g. README_folder"):
        import_denali(tmp_path / "data", store)
    assert not store.exists()


def _comparable(store):
    lab = store.labels().drop(columns=["id"]).sort_values(["object", "zones", "lights", "position", "repeat"])
    hist = {(r.object, r.zones, r.lights, r.position, r.repeat): h for r, h in
            ((type("R", (), c.labels), c.histogram) for c in store.iter_captures())}
    return lab.reset_index(drop=True), hist


def test_export_then_import_reproduces_histograms_and_labels(tree, tmp_path):
    out = tmp_path / "exported"
    with CaptureStore(tmp_path / "a.sqlite") as a, CaptureStore(tmp_path / "b.sqlite") as b:
        import_denali(tree, a)
        res = export_denali(a, out)
        assert (res["folders"], res["files_written"], res["captures"], res["positions"]) == (4, 12, 36, 3)
        assert sorted(p.name for p in out.iterdir()) == sorted(
            [f.replace("i_4inch", "I_4inch") for f in FOLDERS] + ["tag1_positions.json"])
        for folder in FOLDERS:
            for p in POSITIONS:
                written = np.load(out / folder.replace("i_4inch", "I_4inch") / "spad_histogram" / f"{p:03d}.npy")
                assert written.dtype == np.int64 and np.array_equal(written, _data(folder, p))
        import_denali(out, b, positions_json=out / "tag1_positions.json")
        (la, ha), (lb, hb) = _comparable(a), _comparable(b)
        assert la.equals(lb) and ha.keys() == hb.keys()
        assert all(np.array_equal(ha[k], hb[k]) and ha[k].dtype == hb[k].dtype for k in ha)
        again = export_denali(a, out)
        assert (again["files_written"], again["files_unchanged"]) == (0, 12)


def test_export_of_simulated_captures_and_its_refusals(tmp_path):
    s3 = preset("tmf8828-3x3-short")
    xy = positions_xy()
    rng = np.random.default_rng(3)
    with CaptureStore(tmp_path / "s.sqlite") as st:
        for src in ("sim:fast", "sim:other"):
            st.put_many([(rng.integers(0, 99, (3, 3, 128)), dict(object="7", size="8in", position=p, lights="on",
                          repeat=r, source=src, seed=0, x=xy[p, 0], y=xy[p, 1])) for p in (1, 2) for r in range(2)],
                        sensor=s3)
        with pytest.raises(UserError, match="several captures of 7_8in .*filter by source"):
            export_denali(st, tmp_path / "out")
        res = export_denali(st, tmp_path / "out", source="sim:fast")
        assert res["captures"] == 4
        with CaptureStore(tmp_path / "back.sqlite") as back:
            import_denali(tmp_path / "out", back, positions_json=tmp_path / "out" / "tag1_positions.json")
            a, b = st.load(source="sim:fast"), back.load()
            assert np.array_equal(a.histograms, b.histograms)
            cols = ["object", "size", "class_group", "position", "x", "y", "lights", "zones", "repeat"]
            assert a.labels[cols].equals(b.labels[cols])
        with pytest.raises(UserError, match="exists with other data"):
            export_denali(st, tmp_path / "out", source="sim:other")
        assert export_denali(st, tmp_path / "out", source="sim:other", overwrite=True)["files_written"] == 2
        st.put(np.zeros((3, 3, 128), np.int64), dict(object="7", size="8in", position=9, lights="on", repeat=1,
                                                      source="gap", x=0.0, y=0.0), sensor=s3)
        with pytest.raises(UserError, match=r"repeats \[1\] are not 0..R-1"):
            export_denali(st, tmp_path / "gap", source="gap")
        with pytest.raises(UserError, match="no captures to export"):
            export_denali(st, tmp_path / "none", source="nothing")
