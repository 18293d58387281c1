"""Where DENALI's real-trained classifiers succeed: their stored real test predictions, broken down.

DENALI's ``obj_1dcnn.pth`` and ``size_1dcnn.pth`` keep the predicted class of every real test capture in
test order. With DENALI's split reconstructed (:func:`~nlosplan.tasks.denali_protocol.denali_split` over
:func:`~nlosplan.tasks.denali_protocol.protocol_labels`) each prediction has its capture's object, size,
lighting and position, so the real accuracy splits by lighting, size, near/far half and quadrant of the
positions, and by capture folder:

- **near/far half**: the 50 positions with the shortest / longest path LiDAR -> the flash point on the
  relay wall -> the object (:func:`~nlosplan.tasks.metrics.position_quadrants`' ``path_m``);
- **quadrant**: :func:`~nlosplan.tasks.metrics.position_quadrants` (near, far and the two others);
- **folder purity**: per capture folder (object x size x lighting, 120 of them), the share of its test
  captures given its most frequent predicted class; reported as the median over the folders and the
  share of folders whose most frequent prediction is wrong (a folder whose true class ties for the most
  frequent counts as right).

A classifier that recognises the scene's *folder* (its object, size and lighting) more than its position
has pure folders; one that guesses per capture does not.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from nlosplan.errors import UserError
from nlosplan.tasks.denali_protocol import denali_split, protocol_labels, task_labels
from nlosplan.tasks.metrics import position_quadrants

__all__ = ["position_groups", "real_breakdown"]


def position_groups(labels: pd.DataFrame) -> pd.DataFrame:
    """Near/far half and quadrant of every row's position (columns ``half``, ``quadrant``), from all of ``labels``."""
    q = position_quadrants(labels)
    per_position = q.groupby(labels["position"].to_numpy())["path_m"].first()
    median = float(np.median(per_position.to_numpy()))
    half = np.where(q["path_m"].to_numpy() < median, "near", "far")
    return pd.DataFrame({"half": half, "quadrant": q["quadrant"].to_numpy()}, index=labels.index)


def _accuracy_by(correct: np.ndarray, groups: np.ndarray) -> dict:
    return {str(g): float(correct[groups == g].mean()) for g in sorted(set(groups))}


def _purity(pred: np.ndarray, truth: np.ndarray, folders: np.ndarray) -> dict:
    shares, wrong = [], []
    for f in sorted(set(folders)):
        m = folders == f
        counts = np.bincount(pred[m], minlength=int(truth[m].max()) + 1)
        shares.append(counts.max() / m.sum())
        wrong.append(counts[truth[m][0]] < counts.max())  # a folder holds one class; a tie with it is not wrong
    return {"folders": len(shares), "median_modal_share": float(np.median(shares)),
            "wrong_modal_share": float(np.mean(wrong))}


def _one(ckpt, labels: pd.DataFrame, groups: pd.DataFrame) -> dict:
    names = task_labels(labels, ckpt.task)
    _, test = denali_split(ckpt.task, names)
    pred = np.asarray(ckpt.test_predictions)
    if pred.shape != test.shape:
        raise UserError(f"{ckpt.path}: {len(pred)} stored test predictions, DENALI's split has {len(test)} test "
                        "captures")
    truth = np.array([ckpt.classes.index(v) for v in names[test]])
    correct = pred == truth
    lab = labels.iloc[test]
    folders = (lab["object"].astype(str) + "|" + lab["size"].astype(str) + "|" + lab["lights"].astype(str)).to_numpy()
    return {"name": ckpt.name, "task": ckpt.task, "n": int(len(test)), "accuracy": float(correct.mean()),
            "stored_top1": float(ckpt.real),
            "by_lights": _accuracy_by(correct, lab["lights"].astype(str).to_numpy()),
            "by_size": _accuracy_by(correct, lab["size"].astype(str).to_numpy()),
            "by_half": _accuracy_by(correct, groups["half"].to_numpy()[test]),
            "by_quadrant": _accuracy_by(correct, groups["quadrant"].to_numpy()[test]),
            "purity": _purity(pred, truth, folders)}


def real_breakdown(checkpoints) -> dict:
    """Real test accuracy of DENALI's classifiers by lighting, size, near/far half, quadrant, and folder purity.

    Parameters
    ----------
    checkpoints : sequence of DenaliCheckpoint
        Those with stored test predictions are used (DENALI's ``obj_1dcnn`` and ``size_1dcnn``).

    Returns
    -------
    dict
        Per checkpoint name: ``task``, ``n`` (10,800), ``accuracy`` (recomputed: equals ``stored_top1`` when the
        split is DENALI's), ``by_lights``, ``by_size``, ``by_half``, ``by_quadrant`` ({group: accuracy}) and
        ``purity`` (``folders``, ``median_modal_share``, ``wrong_modal_share``).
    """
    labels = protocol_labels()
    groups = position_groups(labels)
    return {ck.name: _one(ck, labels, groups) for ck in checkpoints
            if ck.test_predictions is not None and ck.task != "loc"}
