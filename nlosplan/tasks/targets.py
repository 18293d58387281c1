"""Training targets as the learners take them: localization positions or class indices.

Shared by the trained networks (:mod:`nlosplan.tasks.training`) and the
nearest-neighbour learner (:mod:`nlosplan.tasks.neighbours`), so both read
labels and report bad ones the same way. numpy only (no torch).
"""

from __future__ import annotations

import numpy as np

from nlosplan.errors import UserError

__all__ = ["encode_targets"]


def encode_targets(task: str, targets, n: int, classes=None) -> tuple[np.ndarray, tuple[str, ...] | None]:
    """Check and encode one task's training targets.

    Parameters
    ----------
    task : str
        ``"loc"`` for positions; any other task name is a classification.
    targets : array_like
        ``(n, 2)`` positions in metres for ``"loc"``; ``(n,)`` labels (any type, compared as strings) otherwise.
    n : int
        Number of training captures the targets must match.
    classes : sequence of str, optional
        The class names in index order; default: the sorted distinct labels.

    Returns
    -------
    y : numpy.ndarray
        ``(n, 2)`` float64 positions, or ``(n,)`` int64 class indices into ``names``.
    names : tuple of str or None
        The class names (None for ``"loc"``).

    Raises
    ------
    UserError
        On a wrong shape, a label outside ``classes``, or fewer than two classes.
    """
    if task == "loc":
        y = np.asarray(targets, dtype=np.float64)
        if y.shape != (n, 2):
            raise UserError(f"localization targets must be (N, 2), got {y.shape}")
        return y, None
    raw = np.asarray(targets).astype(str)
    if raw.shape != (n,):
        raise UserError(f"class targets must be (N,), got {raw.shape}")
    names = tuple(sorted(set(raw))) if classes is None else tuple(str(c) for c in classes)
    lookup = {c: i for i, c in enumerate(names)}
    unknown = sorted(set(raw) - set(lookup))
    if unknown:
        raise UserError(f"training labels {', '.join(unknown[:5])} are not among the classes")
    if len(names) < 2:
        raise UserError(f"classification needs at least 2 classes, got {len(names)}")
    return np.array([lookup[c] for c in raw], dtype=np.int64), names
