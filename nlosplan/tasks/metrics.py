"""The scoring module: DENALI's metrics, overall and by group, for every room that scores a model.

Used by the benchmark (:mod:`nlosplan.tasks.benchmark`), the jitter study
(through the benchmark) and the design planner's trained evaluator
(:mod:`nlosplan.planner.design.evaluators`). Definitions are DENALI's
(``benchmark/main_table/metrics.py``):

- classification: top-1 accuracy (argmax), top-k accuracy with
  ``k = min(5, classes)`` (the true class among the k largest scores),
  sklearn macro F1 / precision / recall (``zero_division=0``) over the
  classes present in the targets or predictions;
- localization: errors of (x, y) in metres, pooled over both coordinates:
  ``loc_rmse = sqrt(mean((pred - true)**2))`` (DENALI's ``rmse``) and
  ``mae = mean(|pred - true|)`` over the N x 2 entries (not the Euclidean
  distance), plus per-axis MSE/MAE.

``loc_rmse`` is the one localization metric of nlosplan: the benchmark
table, the studies, the design planner's requirements (``loc<=X``), the
rig's ``--target-rmse`` and the Cramér–Rao comparison all use it
(:data:`METRIC_DEFINITIONS` states it once for help texts, reports and
JSON). One more localization figure, not DENALI's, under its own name:
:func:`loc_rms_distance`, the RMS of the 2-D Euclidean error
``sqrt(mean(|pred - true|^2))`` (= sqrt(2) x ``loc_rmse``).

Breakdowns (the paper's table)
------------------------------
===========  ========================  =======================================
task         metrics                   groups
===========  ========================  =======================================
loc          loc_rmse, mae             all; size; class group
shape        top1, top5, macro F1      all; near/far quadrant; size
size         precision, recall, acc.   all; near/far quadrant; class group
===========  ========================  =======================================

Near/far quadrant
-----------------
DENALI's code does not define it; here it is defined from the labels and
the rig geometry by :func:`position_quadrants`: the gantry positions are
split at the median x and the median y of the localization labels into
four quadrants; each position gets the path length LiDAR -> relay wall ->
object, through the point where the LiDAR's optical axis meets the wall (the
centre of the flash), with the object at that point's height (the gantry
moves in a horizontal plane); "near" is the quadrant with the shortest mean
path, "far" the one with the longest. On the DENALI rig near is x below and
y above the medians (closest to the LiDAR and to the wall; y grows towards
the wall), far is x above and y below.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from nlosplan.errors import UserError

__all__ = ["BREAKDOWNS", "METRICS", "METRIC_DEFINITIONS", "breakdown_rows", "classification_metrics", "loc_rmse",
           "loc_rms_distance", "position_quadrants", "regression_metrics", "top1_accuracy"]

#: Metrics shown per task, in table order (DENALI's key names, but ``loc_rmse`` for its ``rmse``; size accuracy
#: is ``top1_acc``).
METRICS: dict[str, tuple[str, ...]] = {
    "loc": ("loc_rmse", "mae"),
    "shape": ("top1_acc", "top5_acc", "macro_f1"),
    "size": ("macro_precision", "macro_recall", "top1_acc"),
}
#: Breakdown columns per task (label column -> groups shown), after the overall value.
BREAKDOWNS: dict[str, tuple[tuple[str, tuple[str, ...]], ...]] = {
    "loc": (("size", ("4in", "8in")), ("class_group", ("numbers", "letters", "shapes"))),
    "shape": (("quadrant", ("near", "far")), ("size", ("4in", "8in"))),
    "size": (("quadrant", ("near", "far")), ("class_group", ("numbers", "letters", "shapes"))),
}


#: Each metric's definition, stated once: help texts, reports and JSON (``metric_definitions``) print these.
METRIC_DEFINITIONS: dict[str, str] = {
    "loc_rmse": ("localization RMSE, metres, DENALI's: sqrt of the mean of the squared x and y errors pooled over "
                 "the N x 2 entries, sqrt(mean((pred - true)**2))"),
    "loc_rms_distance": ("RMS of the 2-D Euclidean localization error, metres: sqrt(mean_i |pred_i - true_i|^2) "
                         "= sqrt(2) x loc_rmse (not DENALI's; shown where a distance is meant)"),
    "top1_acc": "top-1 accuracy, fraction of test captures whose highest-scoring class is the true one",
}


def top1_accuracy(scores, targets) -> float:
    """Fraction of rows whose largest score is the true class (DENALI's ``top1_acc``).

    Parameters
    ----------
    scores : array_like, shape (N, C)
        Logits or probabilities.
    targets : array_like of int, shape (N,)
        True class indices.
    """
    return float((np.argmax(scores, axis=1) == np.asarray(targets)).mean())


def loc_rmse(predictions, targets) -> float:
    """DENALI's localization RMSE, metres: ``sqrt(mean((pred - true)**2))`` over the N x 2 (x, y) entries.

    Parameters
    ----------
    predictions, targets : array_like, shape (N, 2)
        (x, y) in metres.

    Examples
    --------
    >>> loc_rmse([[0.03, 0.04]], [[0.0, 0.0]])  # 2-D error 5 cm: sqrt((0.03**2 + 0.04**2) / 2)
    0.035355339059327376
    """
    d = np.asarray(predictions, dtype=np.float64) - np.asarray(targets, dtype=np.float64)
    if d.ndim != 2 or d.shape[1] != 2 or d.shape[0] == 0:
        raise UserError(f"predictions and targets must both be (N >= 1, 2), got {d.shape}")
    return math.sqrt(float(np.mean(d ** 2)))


def loc_rms_distance(predictions, targets) -> float:
    """RMS of the 2-D (Euclidean) localization error, metres: ``sqrt(mean_i |pred_i - true_i|^2)``.

    Not DENALI's RMSE (:func:`loc_rmse`, which pools x and y over the N x 2
    entries); this one is ``sqrt(2)`` times larger for the same errors.

    Parameters
    ----------
    predictions, targets : array_like, shape (N, 2)
        (x, y) in metres.
    """
    d = np.asarray(predictions, dtype=np.float64) - np.asarray(targets, dtype=np.float64)
    return math.sqrt(float((d ** 2).sum(axis=1).mean()))


def classification_metrics(scores, targets, *, top_k: int | None = None) -> dict[str, float]:
    """Top-1, top-k and macro F1 / precision / recall of class scores (DENALI's definitions).

    Parameters
    ----------
    scores : array_like, shape (N, C)
        Logits or probabilities; the prediction is the argmax.
    targets : array_like of int, shape (N,)
        True class indices in ``0 .. C-1``.
    top_k : int, optional
        Default ``min(5, C)``.

    Returns
    -------
    dict
        ``top1_acc``, ``top5_acc`` (the top-k accuracy, named as DENALI),
        ``macro_f1``, ``macro_precision``, ``macro_recall``, ``n``.

    Examples
    --------
    >>> classification_metrics([[2.0, 1.0, 0.0], [0.0, 1.0, 2.0]], [0, 1], top_k=2)["top5_acc"]
    1.0
    """
    from sklearn.metrics import f1_score, precision_score, recall_score  # only where classes are scored

    s = np.asarray(scores, dtype=np.float64)
    t = np.asarray(targets).astype(np.int64)
    if s.ndim != 2 or t.shape != (s.shape[0],):
        raise UserError(f"scores must be (N, C) and targets (N,), got {s.shape} and {t.shape}")
    n, c = s.shape
    if n == 0:
        raise UserError("no rows to score")
    k = min(5, c) if top_k is None else int(top_k)
    if not 1 <= k <= c:
        raise UserError(f"top_k={k} must be between 1 and the number of classes {c}")
    pred = s.argmax(axis=1)
    topk = np.argpartition(-s, kth=k - 1, axis=1)[:, :k]
    return {
        "top1_acc": top1_accuracy(s, t),
        "top5_acc": float((topk == t[:, None]).any(axis=1).mean()),
        "macro_f1": float(f1_score(t, pred, average="macro", zero_division=0)),
        "macro_precision": float(precision_score(t, pred, average="macro", zero_division=0)),
        "macro_recall": float(recall_score(t, pred, average="macro", zero_division=0)),
        "n": int(n),
    }


def regression_metrics(predictions, targets) -> dict[str, float]:
    """MSE, RMSE and MAE of (x, y) predictions, pooled and per axis (DENALI's definitions).

    Parameters
    ----------
    predictions, targets : array_like, shape (N, 2)
        (x, y) in metres.

    Returns
    -------
    dict
        ``mse``, ``loc_rmse`` (DENALI's ``rmse``), ``mae`` (metres; over all N x 2 entries),
        ``x_mse``, ``y_mse``, ``x_mae``, ``y_mae``, ``n``.
    """
    p = np.asarray(predictions, dtype=np.float64)
    t = np.asarray(targets, dtype=np.float64)
    if p.shape != t.shape or p.ndim != 2 or p.shape[1] != 2:
        raise UserError(f"predictions and targets must both be (N, 2), got {p.shape} and {t.shape}")
    if p.shape[0] == 0:
        raise UserError("no rows to score")
    d = p - t
    mse = float(np.mean(d ** 2))
    return {
        "mse": mse, "loc_rmse": float(np.sqrt(mse)), "mae": float(np.mean(np.abs(d))),
        "x_mse": float(np.mean(d[:, 0] ** 2)), "y_mse": float(np.mean(d[:, 1] ** 2)),
        "x_mae": float(np.mean(np.abs(d[:, 0]))), "y_mae": float(np.mean(np.abs(d[:, 1]))),
        "n": int(p.shape[0]),
    }


def _flash_point(lidar_position, lidar_forward, wall_center, wall_normal) -> np.ndarray:
    """Where the LiDAR's optical axis meets the wall plane, shape (3,)."""
    denom = float(np.dot(lidar_forward, wall_normal))
    if abs(denom) < 1e-9:
        raise UserError("the LiDAR's optical axis is parallel to the relay wall")
    t = float(np.dot(np.asarray(wall_center) - lidar_position, wall_normal)) / denom
    return np.asarray(lidar_position) + t * np.asarray(lidar_forward)


def position_quadrants(labels: pd.DataFrame, *, lidar=None, wall=None) -> pd.DataFrame:
    """Quadrant of every row's gantry position, and which quadrant is near and which far.

    Parameters
    ----------
    labels : pandas.DataFrame
        Rows with ``x`` and ``y`` (metres). Medians are taken over the distinct
        (x, y) positions, so repeats and unequal row counts do not move them.
        Pass the labels of the whole dataset (not of a test split) so that
        the quadrants do not depend on the split.
    lidar : LidarPose, optional
    wall : Rect, optional
        Rig geometry; default the DENALI rig (:func:`nlosplan.simulators.presets.denali.rig`).

    Returns
    -------
    pandas.DataFrame
        Same index as ``labels``; columns ``quadrant`` (``"near"``, ``"far"``,
        or ``"x low, y low"`` / ``"x high, y high"`` for the other two), ``x_side`` and
        ``y_side`` (``"low"``/``"high"`` against the medians) and ``path_m``
        (LiDAR -> flash point on the wall -> object, metres).

    Notes
    -----
    A position exactly at a median counts as "high". With DENALI's 10 x 10
    grid each quadrant holds 25 positions.
    """
    if lidar is None or wall is None:
        from nlosplan.simulators.presets.denali import rig

        lidar0, wall0, _ = rig()
        lidar, wall = lidar or lidar0, wall or wall0
    xy = labels[["x", "y"]].to_numpy(dtype=np.float64)
    if len(xy) == 0 or not np.isfinite(xy).all():
        raise UserError("quadrants need finite x, y labels")
    uniq = np.unique(xy.round(9), axis=0)
    mx, my = np.median(uniq[:, 0]), np.median(uniq[:, 1])
    x_side = np.where(xy[:, 0] < mx, "low", "high")
    y_side = np.where(xy[:, 1] < my, "low", "high")
    flash = _flash_point(np.asarray(lidar.position), np.asarray(lidar.forward), np.asarray(wall.center),
                         np.asarray(wall.normal))
    obj = np.column_stack([xy, np.full(len(xy), flash[2])])
    path = np.linalg.norm(flash - np.asarray(lidar.position)) + np.linalg.norm(obj - flash, axis=1)
    key = pd.Series(x_side, dtype=object) + "|" + pd.Series(y_side, dtype=object)
    mean_path = pd.Series(path).groupby(key.to_numpy()).mean()
    names = {k: "x {}, y {}".format(*k.split("|")) for k in mean_path.index}
    if len(mean_path) >= 2:
        names[mean_path.idxmin()] = "near"
        names[mean_path.idxmax()] = "far"
    return pd.DataFrame({"quadrant": key.map(names).to_numpy(), "x_side": x_side, "y_side": y_side,
                         "path_m": path}, index=labels.index)


def _task_metrics(task: str, scores: np.ndarray, targets: np.ndarray) -> dict[str, float]:
    if task == "loc":
        return regression_metrics(scores, targets)
    return classification_metrics(scores, targets)


def breakdown_rows(task: str, labels: pd.DataFrame, scores, targets, *, quadrant=None) -> list[dict]:
    """The table's values for one task: overall and per group, as tidy rows.

    Parameters
    ----------
    task : {"loc", "shape", "size"}
    labels : pandas.DataFrame
        Labels of the N scored rows (``size``, ``class_group`` used).
    scores : array_like
        (N, 2) predicted (x, y) for ``"loc"``, (N, C) class scores otherwise.
    targets : array_like
        (N, 2) true (x, y), or (N,) true class indices.
    quadrant : array_like of str, shape (N,), optional
        Quadrant of each row (from :func:`position_quadrants` over the whole
        dataset); computed from ``labels`` when omitted.

    Returns
    -------
    list of dict
        One per (metric, group): ``group_by`` (``"all"``, ``"size"``,
        ``"class_group"``, ``"quadrant"``), ``group``, ``metric``, ``value``,
        ``n`` (rows in the group). Groups with no rows are left out.
    """
    if task not in METRICS:
        raise UserError(f"unknown task {task!r}; allowed: {', '.join(METRICS)}")
    scores, targets = np.asarray(scores), np.asarray(targets)
    lab = labels.reset_index(drop=True).copy()
    if len(lab) != len(scores):
        raise UserError(f"{len(lab)} label rows for {len(scores)} predictions")
    if any(col == "quadrant" for col, _ in BREAKDOWNS[task]):
        lab["quadrant"] = (np.asarray(quadrant) if quadrant is not None
                           else position_quadrants(lab)["quadrant"].to_numpy())
    parts = [("all", "all", np.ones(len(lab), bool))]
    for col, groups in BREAKDOWNS[task]:
        values = lab[col].astype(str).to_numpy()
        parts += [(col, g, values == g) for g in groups]
    rows = []
    for group_by, group, mask in parts:
        if not mask.any():
            continue
        m = _task_metrics(task, scores[mask], targets[mask])
        rows += [{"group_by": group_by, "group": group, "metric": k, "value": m[k], "n": int(mask.sum())}
                 for k in METRICS[task]]
    return rows
