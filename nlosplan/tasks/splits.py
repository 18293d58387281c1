"""Train/test splits of a :class:`~nlosplan.data.dataset.Dataset`, as DENALI's benchmark makes them.

Random splits (``benchmark/main_table/data.py``)
    70/30, ``random_state=42``, sklearn ``train_test_split``: plain for
    localization, stratified on the label for shape and size classification.
    Rows that are repeats of one scene go to the same side (with one row per
    scene, e.g. after :meth:`Dataset.mean_over_repeats`, this is exactly
    DENALI's row split; with repeats kept it is DENALI's "random grouped").
Held-out splits (``benchmark/generalization/splits.py``)
    ``positions``: 30 % of the gantry positions held out (70 train / 30 test
    of DENALI's 100); ``objects``: 30 % of the object classes held out (21 / 9;
    for localization and size only: a held-out class cannot be classified);
    ``sizes``: train on one size, test on the other (``sizes`` or
    ``sizes:4in`` trains on 4 in as DENALI; ``sizes:8in`` the reverse; not for
    the size task).

Every split is a pure function of the labels and the seed.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import pandas as pd
from sklearn.model_selection import train_test_split

from nlosplan.errors import UserError
from nlosplan.data.dataset import Dataset, scene_groups
from nlosplan.tasks.names import SPLITS, TASK_LABEL, TASKS  # noqa: F401 (SPLITS re-exported)

__all__ = ["SPLITS", "Split", "heldout_objects", "heldout_positions", "heldout_sizes", "make_split",
           "random_split", "split_applies", "stratified_split", "task_random_split"]

#: Split kinds accepted by :func:`make_split` (``sizes:8in`` trains on 8 in).


@dataclass(frozen=True)
class Split:
    """Row indices of the training and test sets.

    Parameters
    ----------
    train, test : ndarray of int, shape (n_train,), (n_test,)
        Disjoint row indices, ascending.
    kind : str
        One of :data:`SPLITS`.
    info : dict
        What was held out (positions, objects, sizes) and the seed.
    """

    train: np.ndarray
    test: np.ndarray
    kind: str
    info: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        tr = np.sort(np.asarray(self.train, dtype=np.int64))
        te = np.sort(np.asarray(self.test, dtype=np.int64))
        if np.intersect1d(tr, te).size:
            raise RuntimeError("split has rows on both sides")
        object.__setattr__(self, "train", tr)
        object.__setattr__(self, "test", te)


def _check_fraction(test_size: float) -> None:
    if not 0 < test_size < 1:
        raise UserError(f"test_size={test_size} must be between 0 and 1")


def random_split(n: int, *, test_size: float = 0.3, seed: int = 42) -> Split:
    """Plain random split of ``n`` rows (DENALI's localization split).

    Parameters
    ----------
    n : int
        Number of rows.
    test_size : float
        Fraction held out for testing.
    seed : int
        sklearn ``random_state``.

    Returns
    -------
    Split
    """
    _check_fraction(test_size)
    if n < 2:
        raise UserError(f"cannot split {n} row(s) into training and test sets")
    tr, te = train_test_split(np.arange(n), test_size=test_size, shuffle=True, random_state=seed)
    return Split(tr, te, "random", {"seed": seed, "test_size": test_size})


def stratified_split(y, *, test_size: float = 0.3, seed: int = 42) -> Split:
    """Random split stratified on the labels ``y`` (DENALI's classification split).

    Parameters
    ----------
    y : array_like, shape (n,)
        Class labels.
    test_size : float
    seed : int

    Raises
    ------
    UserError
        A class with fewer than 2 rows, or too few rows for every class on both sides.
    """
    _check_fraction(test_size)
    y = np.asarray(y)
    try:
        tr, te = train_test_split(np.arange(len(y)), test_size=test_size, stratify=y, random_state=seed)
    except ValueError as exc:
        raise UserError(f"cannot stratify {len(y)} rows on their labels: {exc}") from None
    return Split(tr, te, "random", {"seed": seed, "test_size": test_size, "stratified": True})


def _rows_of(groups: np.ndarray, chosen: np.ndarray) -> np.ndarray:
    return np.flatnonzero(np.isin(groups, chosen))


def task_random_split(dataset: Dataset, task: str, *, test_size: float = 0.3, seed: int = 42) -> Split:
    """DENALI's random split for a task: plain for ``"loc"``, stratified on the label otherwise.

    Repeats of one scene stay on one side (splits are drawn over scenes).
    """
    groups = scene_groups(dataset.labels)  # a scene's repeats share its number
    first = pd.Series(np.arange(len(groups))).groupby(groups).first().to_numpy()
    if task == "loc":
        s = random_split(len(first), test_size=test_size, seed=seed)
    else:
        s = stratified_split(dataset.labels[TASK_LABEL[task]].to_numpy()[first], test_size=test_size, seed=seed)
    return Split(_rows_of(groups, s.train), _rows_of(groups, s.test), "random", s.info)


def _held_out_values(values, test_size: float, seed: int) -> tuple[list, list]:
    """Sorted distinct values split into (train, test) by a seeded permutation; ``round(test_size * n)`` held out."""
    uniq = pd.unique(pd.Series(values)).tolist()
    try:
        uniq = sorted(uniq)
    except TypeError:
        uniq = sorted(uniq, key=str)
    n_test = int(round(test_size * len(uniq)))
    if len(uniq) < 2 or not 0 < n_test < len(uniq):
        raise UserError(f"cannot hold out {test_size:.0%} of {len(uniq)} distinct value(s)")
    perm = np.random.default_rng(seed).permutation(len(uniq))
    held = set(perm[:n_test].tolist())
    test = [u for i, u in enumerate(uniq) if i in held]
    train = [u for i, u in enumerate(uniq) if i not in held]
    return train, test


def heldout_positions(dataset: Dataset, *, test_size: float = 0.3, seed: int = 42) -> Split:
    """Held-out gantry positions: every row at a test position goes to the test set.

    Parameters
    ----------
    dataset : Dataset
        Labels need ``position`` >= 0 (else the (x, y) label identifies the position).
    test_size : float
        Fraction of the distinct positions held out (30 of DENALI's 100).
    seed : int
    """
    _check_fraction(test_size)
    lab = dataset.labels
    key = (lab["position"].astype(int).to_numpy() if (lab["position"] >= 0).all()
           else (lab["x"].round(6).astype(str) + "," + lab["y"].round(6).astype(str)).to_numpy())
    train, test = _held_out_values(key, test_size, seed)
    te = np.flatnonzero(np.isin(key, test))
    tr = np.flatnonzero(np.isin(key, train))
    return Split(tr, te, "positions", {"seed": seed, "test_positions": [v if isinstance(v, str) else int(v)
                                                                          for v in test]})


def heldout_objects(dataset: Dataset, *, test_size: float = 0.3, seed: int = 42) -> Split:
    """Held-out object classes (21 train / 9 test of DENALI's 30): for localization and size only."""
    _check_fraction(test_size)
    obj = dataset.labels["object"].astype(str).to_numpy()
    train, test = _held_out_values(obj, test_size, seed)
    return Split(np.flatnonzero(np.isin(obj, train)), np.flatnonzero(np.isin(obj, test)), "objects",
                 {"seed": seed, "test_objects": test})


def heldout_sizes(dataset: Dataset, *, train_size: str = "4in") -> Split:
    """Train on one object size, test on the other (DENALI trains on 4 in, tests on 8 in)."""
    size = dataset.labels["size"].astype(str).to_numpy()
    present = sorted(set(size))
    if train_size not in present or len(present) < 2:
        raise UserError(f"held-out sizes need rows of size {train_size} and another size; the dataset has "
                        f"{', '.join(present) or 'none'}")
    tr = np.flatnonzero(size == train_size)
    te = np.flatnonzero(size != train_size)
    return Split(tr, te, f"sizes:{train_size}", {"train_size": train_size,
                                                 "test_sizes": [s for s in present if s != train_size]})


def split_applies(kind: str, task: str) -> str | None:
    """Why a split does not apply to a task (``None`` when it does).

    Held-out objects cannot be classified into their own class, and held-out
    sizes cannot be classified by size (DENALI reports these as n/a).
    """
    if kind == "objects" and task == "shape":
        return "held-out object classes cannot be classified (n/a, as DENALI)"
    if kind.startswith("sizes") and task == "size":
        return "a held-out size cannot be classified (n/a, as DENALI)"
    return None


def make_split(dataset: Dataset, kind: str, task: str, *, seed: int = 42, test_size: float = 0.3) -> Split:
    """The split ``kind`` of :data:`SPLITS` for ``task`` (``"loc"``, ``"shape"`` or ``"size"``).

    Parameters
    ----------
    dataset : Dataset
    kind : str
        ``"random"``, ``"positions"``, ``"objects"``, ``"sizes"`` (= ``"sizes:4in"``) or ``"sizes:8in"``.
    task : str
    seed : int
        Seed of the random and held-out choices (42, as DENALI).
    test_size : float
        Test fraction (rows, positions or object classes).

    Returns
    -------
    Split

    Raises
    ------
    UserError
        Unknown kind or task, a kind that does not apply to the task (see
        :func:`split_applies`), or too little data to split.
    """
    if kind not in SPLITS:
        raise UserError(f"unknown split {kind!r}; allowed: {', '.join(SPLITS)}")
    if task not in TASKS:
        raise UserError(f"unknown task {task!r}; allowed: {', '.join(TASKS)}")
    why = split_applies(kind, task)
    if why:
        raise UserError(f"split {kind!r} does not apply to task {task!r}: {why}")
    if kind == "random":
        return task_random_split(dataset, task, test_size=test_size, seed=seed)
    if kind == "positions":
        return heldout_positions(dataset, test_size=test_size, seed=seed)
    if kind == "objects":
        return heldout_objects(dataset, test_size=test_size, seed=seed)
    return heldout_sizes(dataset, train_size=kind.split(":")[1] if ":" in kind else "4in")
