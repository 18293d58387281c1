"""k nearest neighbours under DENALI's protocol: a training-free cell beside DENALI's recipe in ``bench denali``.

DENALI's recipe needs 8-14 min per 1D CNN cell at full budget on 2 idle CPU cores; the k-nearest-neighbour learner
of the design planner (:mod:`nlosplan.tasks.neighbours`: principal components of square-root counts, their number
and k chosen on a seeded 15 % of the training captures) takes about a minute on DENALI's 25,200 training captures. :func:`knn_cell` runs it on DENALI's
exact split (:func:`~nlosplan.tasks.denali_protocol.denali_split`) and returns the same
:class:`~nlosplan.tasks.denali_result.CellResult` as a recipe cell, so ``bench denali --models knn`` prints it in the
same table: with no epochs and k chosen without the test set, its best-on-test, last-epoch and validation-chosen
figures are one test-blind number. Table 1 has no such learner: its ``real`` is empty.
"""

from __future__ import annotations

import time

import numpy as np

from nlosplan.tasks.denali_result import CellResult

__all__ = ["KNN", "knn_cell"]

#: The cell's model name in ``bench denali`` (``--models knn``).
KNN = "knn"


def knn_cell(histograms, targets, task: str, *, seed: int = 42) -> CellResult:
    """Fit k nearest neighbours on DENALI's training split and score its test split.

    Parameters
    ----------
    histograms : array_like, shape (N, rows, cols, bins)
        Counts in DENALI's capture order.
    targets : array_like
        (N, 2) x, y in metres for ``"loc"``; (N,) class names otherwise.
    task : {"loc", "shape", "size"}
    seed : int
        Seed of the validation share that chooses k (the split stays DENALI's).

    Returns
    -------
    CellResult
        ``predicted`` = ``predicted_last_epoch`` = ``predicted_validation_epoch`` (test-blind), ``epochs`` 0,
        ``history`` the validation score of every k tried, ``settings`` ``{"k", "k_choices", "components", "component_choices", "transform"}``;
        ``n_train`` every training row (all are neighbours), ``n_val`` the share among them that chose k.
    """
    from nlosplan.tasks.denali_protocol import denali_split
    from nlosplan.tasks.metrics import loc_rmse, top1_accuracy
    from nlosplan.tasks.neighbours import COMPONENT_CHOICES, K_CHOICES, fit_neighbours

    t0 = time.perf_counter()
    x = np.asarray(histograms, dtype=np.float32)
    if task == "loc":
        y = np.asarray(targets, dtype=np.float64)
        classes = None
    else:
        y = np.asarray(targets).astype(str)
        classes = tuple(sorted(set(y)))
    train, test = (np.asarray(i, dtype=np.int64) for i in denali_split(task, y))
    model = fit_neighbours(x[train], y[train], task=task, classes=classes, seed=seed)
    out = model.predict(x[test])
    if task == "loc":
        value, pred, metric = loc_rmse(out, y[test]), out, "loc_rmse"
    else:
        truth = np.array([classes.index(v) for v in y[test]])
        value, pred, metric = top1_accuracy(out, truth), out.argmax(axis=1), "top1_acc"
    return CellResult(task=task, model=KNN, metric=metric, selection="validation share", mode="denali",
                      predicted=float(value), best_epoch=0, predicted_last_epoch=float(value), epochs=0,
                      predicted_validation_epoch=float(value), validation_epoch=None, history=tuple(model.history),
                      n_train=int(model.n_train), n_val=int(model.n_val), n_test=int(len(test)),
                      test_index=test, predictions={"best": pred, "last": pred, "validation": pred}, classes=classes,
                      settings={"k": int(model.k), "k_choices": list(K_CHOICES), "components": int(model.components),
                                "component_choices": list(COMPONENT_CHOICES),
                                "transform": "sqrt(max(counts, 0)), principal components"},
                      preprocessing={"transform": "sqrt"}, seconds=time.perf_counter() - t0, device="cpu",
                      seed=int(seed))
