"""Metrics: DENALI's definitions (by hand and against sklearn), breakdown groups, near/far quadrants."""

import numpy as np
import pandas as pd
import pytest
from sklearn.metrics import accuracy_score, f1_score, precision_score, recall_score, top_k_accuracy_score

from nlosplan.errors import UserError
from nlosplan.tasks.metrics import (METRICS, breakdown_rows, classification_metrics, position_quadrants,
                                    regression_metrics)


def test_classification_by_hand():
    # 4 rows, 3 classes; predictions 0, 1, 1, 2 for targets 0, 1, 2, 2
    scores = np.array([[3, 1, 0], [0, 2, 1], [0, 2, 1.5], [0, 1, 2]], float)
    m = classification_metrics(scores, [0, 1, 2, 2], top_k=2)
    assert m["top1_acc"] == 0.75
    assert m["top5_acc"] == 1.0  # the third row's true class 2 is second
    # per class precision 1, 1/2, 1; recall 1, 1, 1/2; F1 1, 2/3, 2/3
    assert m["macro_precision"] == pytest.approx((1 + 0.5 + 1) / 3)
    assert m["macro_recall"] == pytest.approx((1 + 1 + 0.5) / 3)
    assert m["macro_f1"] == pytest.approx((1 + 2 / 3 + 2 / 3) / 3)
    assert classification_metrics(scores, [0, 1, 2, 2], top_k=1)["top5_acc"] == 0.75


def test_classification_matches_sklearn_and_default_k():
    rng = np.random.default_rng(3)
    scores = rng.normal(size=(200, 30))
    y = rng.integers(0, 30, 200)
    m = classification_metrics(scores, y)
    pred = scores.argmax(1)
    assert m["top1_acc"] == pytest.approx(accuracy_score(y, pred))
    assert m["top5_acc"] == pytest.approx(top_k_accuracy_score(y, scores, k=5, labels=range(30)))
    assert m["macro_f1"] == pytest.approx(f1_score(y, pred, average="macro", zero_division=0))
    assert m["macro_precision"] == pytest.approx(precision_score(y, pred, average="macro", zero_division=0))
    assert m["macro_recall"] == pytest.approx(recall_score(y, pred, average="macro", zero_division=0))
    two = classification_metrics(scores[:, :2], y % 2)  # k = min(5, 2) = 2: top-k is always right
    assert two["top5_acc"] == 1.0


def test_regression_pools_both_coordinates():
    pred = np.array([[1.0, 0.3], [1.1, 0.5]])
    true = np.array([[1.0, 0.5], [1.2, 0.5]])
    m = regression_metrics(pred, true)
    # errors 0, -0.2, -0.1, 0 over 4 entries
    assert m["mse"] == pytest.approx((0.04 + 0.01) / 4)
    assert m["loc_rmse"] == pytest.approx(np.sqrt(0.05 / 4))
    assert m["mae"] == pytest.approx(0.3 / 4)
    assert m["x_mae"] == pytest.approx(0.05) and m["y_mae"] == pytest.approx(0.1)
    with pytest.raises(UserError, match=r"must both be \(N, 2\)"):
        regression_metrics(pred, true[:, :1])


def _labels(n):
    return pd.DataFrame({"size": ["4in", "8in"] * (n // 2), "class_group": ["numbers", "letters", "shapes", "shapes"]
                         * (n // 4), "x": np.linspace(1.0, 1.3, n), "y": np.linspace(0.2, 0.5, n)[::-1]})


@pytest.mark.parametrize("task", ["loc", "shape", "size"])
def test_breakdown_groups_and_counts(task):
    lab = _labels(40)
    rng = np.random.default_rng(0)
    if task == "loc":
        targets = lab[["x", "y"]].to_numpy()
        scores = targets + rng.normal(0, 0.01, targets.shape)
    else:
        targets = rng.integers(0, 5 if task == "shape" else 2, 40)
        scores = rng.normal(size=(40, 5 if task == "shape" else 2))
    quad = np.array(["near", "far", "x low, y low", "x high, y high"] * 10)
    rows = pd.DataFrame(breakdown_rows(task, lab, scores, targets, quadrant=quad))
    counts = rows.groupby(["group_by", "group"])["n"].first().to_dict()
    assert counts[("all", "all")] == 40
    if task == "loc":
        assert counts[("size", "4in")] == counts[("size", "8in")] == 20
    else:
        assert counts[("quadrant", "near")] == counts[("quadrant", "far")] == 10
    if task != "shape":
        assert (counts[("class_group", "numbers")], counts[("class_group", "letters")],
                counts[("class_group", "shapes")]) == (10, 10, 20)
    assert set(rows["metric"]) == set(METRICS[task])
    # a group's value is the metric over its rows alone
    sel = lab["size"].to_numpy() == "8in"
    key = "loc_rmse" if task == "loc" else "top1_acc"
    grp = "size" if task != "size" else "class_group"
    if grp == "size":
        want = (regression_metrics(scores[sel], targets[sel]) if task == "loc"
                else classification_metrics(scores[sel], targets[sel]))[key]
        got = rows.query("group == '8in' and metric == @key")["value"].item()
        assert got == pytest.approx(want)


def test_quadrants_on_the_denali_positions():
    from nlosplan.denali import positions_xy
    from nlosplan.simulators.presets.denali import rig

    xy = positions_xy()
    lab = pd.DataFrame({"x": xy[:, 0], "y": xy[:, 1]})
    q = position_quadrants(lab)
    counts = q["quadrant"].value_counts()
    assert len(counts) == 4 and set(counts) == {25}
    near, far = q["quadrant"] == "near", q["quadrant"] == "far"
    # near: x below and y above the medians (towards the LiDAR and the wall); far: the opposite
    assert set(q.loc[near, "x_side"]) == {"low"} and set(q.loc[near, "y_side"]) == {"high"}
    assert set(q.loc[far, "x_side"]) == {"high"} and set(q.loc[far, "y_side"]) == {"low"}
    lidar, wall, _ = rig()
    to_lidar = np.linalg.norm(xy - lidar.position[:2], axis=1)
    to_wall = np.abs((np.column_stack([xy, np.full(100, wall.center[2])]) - wall.center) @ wall.normal)
    means = {name: (to_lidar[q["quadrant"] == name].mean(), to_wall[q["quadrant"] == name].mean())
             for name in counts.index}
    # near is the closest to the wall; the quadrants that share a side are within a few mm of each other in
    # the other distance (the LiDAR sits at about the median y): near and far are the extremes within 5 mm
    assert means["near"][1] == min(m[1] for m in means.values())
    assert means["far"][1] > max(m[1] for m in means.values()) - 0.005
    assert means["near"][0] < min(m[0] for m in means.values()) + 0.005
    assert means["far"][0] > max(m[0] for m in means.values()) - 0.005
    path = q.groupby("quadrant")["path_m"].mean()
    assert path.idxmin() == "near" and path.idxmax() == "far" and path["far"] - path["near"] > 0.2


def test_quadrants_ignore_repeats_and_row_order():
    from nlosplan.denali import positions_xy

    xy = positions_xy()
    lab = pd.DataFrame({"x": xy[:, 0], "y": xy[:, 1]})
    tripled = pd.concat([lab, lab.iloc[:10], lab.iloc[:10]], ignore_index=True).sample(frac=1, random_state=0)
    q1 = position_quadrants(lab)["quadrant"]
    q2 = position_quadrants(tripled)["quadrant"]
    assert (q2.sort_index().iloc[:100].to_numpy() == q1.to_numpy()).all()
