"""DENALI's protocol as data: its capture order, its split (checked against its checkpoints' stored test
predictions), its names, and the packaged Table 1 (checked against ../shared's copy)."""

import re

import numpy as np
import pytest

from nlosplan.errors import UserError
from nlosplan.tasks.denali_protocol import (DENALI_CLASSES, capture_order, denali_split, folder_name,
                                            protocol_labels, table1, task_labels)


@pytest.fixture(scope="module")
def labels():
    return protocol_labels()


def test_denalis_order_folders_as_strings_then_positions_then_repeats(labels):
    assert len(labels) == 36_000
    first = labels.iloc[:4][["object", "size", "lights", "position", "repeat"]].values.tolist()
    assert first == [["0", "4in", "off", 0, 0], ["0", "4in", "off", 0, 1], ["0", "4in", "off", 0, 2],
                     ["0", "4in", "off", 1, 0]]
    folders = [folder_name(o, s, z, li) for o, s, z, li in labels[["object", "size", "zones", "lights"]].values]
    starts = sorted(set(folders), key=folders.index)
    assert starts == sorted(starts) and len(starts) == 120      # "lightoff" < "lighton", "4inch" < "8inch"
    assert folder_name("semicircle", "4in", "3x3", "on") == "halfcircle_4inch_3x3_lighton_NLOSdata"
    # the mesh "semicircle" sorts where DENALI's "halfcircle" does: after "downarrow", before "hexagon"
    objs = list(dict.fromkeys(labels["object"]))
    assert objs.index("semicircle") == objs.index("downarrow") + 1 == objs.index("hexagon") - 1
    shuffled = labels.sample(frac=1.0, random_state=3).reset_index(drop=True)
    back = shuffled.iloc[capture_order(shuffled)].reset_index(drop=True)
    assert back[["object", "size", "lights", "position", "repeat"]].equals(
        labels[["object", "size", "lights", "position", "repeat"]])


def test_order_refuses_what_has_no_denali_name_or_appears_twice(labels):
    twice = labels.iloc[[0, 0]].reset_index(drop=True)
    with pytest.raises(UserError, match="share folder, position and repeat"):
        capture_order(twice)
    odd = labels.iloc[:2].copy()
    odd["lights"] = "dim"
    with pytest.raises(UserError, match="dim have no DENALI folder name"):
        capture_order(odd)
    with pytest.raises(UserError, match="label column"):
        capture_order(labels.drop(columns=["repeat"]))


def test_class_names_are_denalis_sorted(labels):
    assert len(DENALI_CLASSES) == 30 and list(DENALI_CLASSES) == sorted(DENALI_CLASSES)
    assert "halfcircle" in DENALI_CLASSES and "semicircle" not in DENALI_CLASSES and "I" in DENALI_CLASSES
    assert set(task_labels(labels, "shape")) == set(DENALI_CLASSES)
    assert set(task_labels(labels, "size")) == {"4inch", "8inch"}
    xy = task_labels(labels, "loc")
    assert xy.shape == (36_000, 2) and np.isfinite(xy).all()


def test_the_split_is_denalis_real_one(labels, shared_data):
    """The stored real test predictions of DENALI's 1D CNNs score their stored top-1 to all digits."""
    from nlosplan.tasks.denali_checkpoints import load_denali_checkpoint

    for name, task in (("obj_1dcnn", "shape"), ("size_1dcnn", "size")):
        ck = load_denali_checkpoint(shared_data / "denali" / "checkpoints" / f"{name}.pth")
        names = task_labels(labels, task)
        train, test = denali_split(task, names)
        assert len(train) == 25_200 and len(test) == 10_800 and not np.intersect1d(train, test).size
        truth = np.array([ck.classes.index(v) for v in names[test]])
        assert (ck.test_predictions == truth).mean() == ck.real     # exactly: 0.38768518... and 0.94685185...
    assert ck.real == pytest.approx(0.9468518518518518, abs=1e-15)
    # a split that is not DENALI's (another seed) does not reproduce it
    _, other = denali_split("size", names, seed=41)
    assert abs((ck.test_predictions == np.array([ck.classes.index(v) for v in names[other]])).mean() - ck.real) > 0.2


def test_localization_split_is_a_plain_shuffle(labels):
    train, test = denali_split("loc", task_labels(labels, "loc"))
    assert len(test) == 10_800 and sorted(np.concatenate([train, test])) == list(range(36_000))
    with pytest.raises(UserError, match="split of 3 captures"):
        denali_split("size", ["4inch", "8inch", "8inch"])


def test_packaged_table1_is_the_shared_copy(shared_data):
    text = (shared_data / "denali" / "benchmark_table1.md").read_text()
    rows = {m.group(1): [[float(v.strip(" *")) for v in cell.split("/")] for cell in re.split(r"\s*\|\s*", m.group(2))]
            for m in re.finditer(r"^\| (localization|shape|size)[^|]*\| (.+?) \|$", text, re.M)}
    got = table1()["values"]
    models = ("mlp", "cnn1d", "cnn3d", "transformer")
    for i, model in enumerate(models):
        assert [got["loc"][model]["loc_rmse"], got["loc"][model]["mae"]] == rows["localization"][i]
        assert [got["shape"][model][k] for k in ("top1_acc", "top5_acc", "macro_f1")] == rows["shape"][i]
        assert [got["size"][model]["top1_acc"]] == rows["size"][i]
    assert got["loc"]["cnn1d"]["loc_rmse"] == 0.0456 and got["shape"]["cnn1d"]["top1_acc"] == 0.3876
    assert "NikhilBehari/denali" in table1()["source"]
