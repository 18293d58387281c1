"""Splits: DENALI's 70/30 random and stratified splits, held-out positions, objects and sizes."""

import numpy as np
import pytest
from sklearn.model_selection import train_test_split
from synthetic_tasks import synthetic_dataset

from nlosplan.errors import UserError
from nlosplan.tasks.splits import (heldout_objects, heldout_positions, heldout_sizes, make_split, random_split,
                                   stratified_split)


@pytest.fixture(scope="module")
def ds():
    return synthetic_dataset(n_side=5, bins=16)  # 6 objects x 2 sizes x 25 positions = 300 rows


def _disjoint_cover(split, n):
    assert np.intersect1d(split.train, split.test).size == 0
    assert np.array_equal(np.sort(np.concatenate([split.train, split.test])), np.arange(n))


def test_random_split_is_sklearns_with_seed_42():
    s = random_split(100)
    tr, te = train_test_split(np.arange(100), test_size=0.3, shuffle=True, random_state=42)
    assert np.array_equal(s.test, np.sort(te)) and np.array_equal(s.train, np.sort(tr))
    assert len(s.test) == 30
    _disjoint_cover(s, 100)


def test_splits_are_deterministic_and_seed_dependent(ds):
    a, b, c = (make_split(ds, "random", "loc", seed=s) for s in (42, 42, 7))
    assert np.array_equal(a.test, b.test) and not np.array_equal(a.test, c.test)
    p1, p2 = make_split(ds, "positions", "shape", seed=1), make_split(ds, "positions", "shape", seed=1)
    assert np.array_equal(p1.test, p2.test)


def test_stratified_split_keeps_class_proportions(ds):
    s = make_split(ds, "random", "shape")
    _disjoint_cover(s, len(ds))
    test_counts = ds.labels["object"].iloc[s.test].value_counts()
    assert len(test_counts) == 6 and set(test_counts) == {15}  # 30 % of 50 rows per object
    s2 = stratified_split(ds.labels["size"])
    assert ds.labels["size"].iloc[s2.test].value_counts().to_dict() == {"4in": 45, "8in": 45}


def test_repeats_of_a_scene_stay_together():
    ds3 = synthetic_dataset(objects=("1", "A"), n_side=4, bins=16, repeats=3)
    s = make_split(ds3, "random", "loc")
    keys = ds3.labels[["object", "size", "position"]].astype(str).agg("|".join, axis=1)
    assert not set(keys.iloc[s.train]) & set(keys.iloc[s.test])
    assert len(s.test) == 3 * 20  # 64 scenes; sklearn rounds the test share up: ceil(0.3 * 64)


def test_heldout_positions(ds):
    s = heldout_positions(ds)
    _disjoint_cover(s, len(ds))
    pos = ds.labels["position"].to_numpy()
    assert not set(pos[s.train]) & set(pos[s.test])
    assert len(set(pos[s.test])) == round(0.3 * 25) and s.info["test_positions"] == sorted(set(pos[s.test]))


def test_heldout_objects(ds):
    s = heldout_objects(ds)
    _disjoint_cover(s, len(ds))
    obj = ds.labels["object"].to_numpy()
    assert not set(obj[s.train]) & set(obj[s.test])
    assert len(set(obj[s.test])) == round(0.3 * 6) == len(s.info["test_objects"])


@pytest.mark.parametrize("train_size,test_size", [("4in", "8in"), ("8in", "4in")])
def test_heldout_sizes_both_ways(ds, train_size, test_size):
    s = heldout_sizes(ds, train_size=train_size)
    _disjoint_cover(s, len(ds))
    size = ds.labels["size"].to_numpy()
    assert set(size[s.train]) == {train_size} and set(size[s.test]) == {test_size}
    assert np.array_equal(make_split(ds, f"sizes:{train_size}", "loc").test, s.test)
    if train_size == "4in":
        assert np.array_equal(make_split(ds, "sizes", "shape").test, s.test)


@pytest.mark.parametrize("kind,task", [("objects", "shape"), ("sizes", "size"), ("sizes:8in", "size")])
def test_ill_posed_splits_are_refused(ds, kind, task):
    with pytest.raises(UserError, match="does not apply"):
        make_split(ds, kind, task)


def test_unknown_split_and_bad_fraction(ds):
    with pytest.raises(UserError, match="unknown split"):
        make_split(ds, "diagonal", "loc")
    with pytest.raises(UserError, match="test_size"):
        random_split(10, test_size=1.5)


def test_scene_groups_number_scenes_in_order_of_appearance_as_their_keys_do():
    import pandas as pd

    from nlosplan.data.dataset import scene_groups, scene_keys

    # repeats of one scene apart, a later scene first seen between them, a size or the lighting differing
    labels = pd.DataFrame({"object": ["b", "a", "b", "a", "a", "b"], "size": ["4in", "4in", "4in", "4in", "8in", "4in"],
                           "position": [3, 1, 3, 1, 1, 3], "lights": ["on"] * 5 + ["off"],
                           "zones": ["3x3"] * 6, "source": ["sim"] * 6, "repeat": [0, 0, 1, 1, 0, 2]})
    g = scene_groups(labels)
    assert g.tolist() == [0, 1, 0, 1, 2, 3]
    assert np.array_equal(g, pd.factorize(scene_keys(labels))[0])
    labels.loc[[1, 3], "size"] = None  # a missing label is a value of its own, not a dropped row
    assert scene_groups(labels).tolist() == [0, 1, 0, 1, 2, 3]
