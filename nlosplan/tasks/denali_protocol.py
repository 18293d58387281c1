"""DENALI's benchmark protocol as data: its names, its capture order, its split, its published Table 1.

Facts from DENALI's repository (github.com/NikhilBehari/denali @ 9e10832, ``benchmark/main_table``:
``data.py``, ``loaders.py``, ``training.py``; MIT), read, not copied:

- **Captures** are the 3x3 histograms of the 30 base objects x 2 sizes x 100 positions x 2 lightings,
  each of the 3 repeats its own sample (36,000).
- **Order** (``DataSet.from_raw_captures`` then ``query_data``): capture folders
  ``f"{object}_{size}_{zones}_{lighting}_NLOSdata"`` sorted as strings, with DENALI's names
  (``halfcircle`` for the mesh ``semicircle``; the 4 in ``i`` mesh is ``I``; sizes ``4inch``/``8inch``;
  lightings ``lighton``/``lightoff``); in a folder the positions ascending; per position its repeats.
- **Split**: scikit-learn's ``train_test_split(np.arange(n), test_size=0.3, random_state=42)``, stratified on
  the label names (object or size) for the classification tasks, shuffled for localization. In that order
  the split reproduces DENALI's real one (the stored test predictions of its checkpoints score exactly
  their stored top-1: a test checks it).
- **Labels**: classes are the sorted label names (scikit-learn's ``LabelEncoder``); localization targets
  are DENALI's tag-1 (x, y) (:func:`nlosplan.denali.positions_xy`), metres.

Simulated captures put in this order have the same (object, size, lighting, position, repeat) in the test
set as DENALI's real test set. This module needs no torch (scikit-learn only inside :func:`denali_split`).
"""

from __future__ import annotations

import json
from functools import lru_cache
from importlib import resources

import numpy as np
import pandas as pd

from nlosplan.denali import DENALI_OBJECTS, N_POSITIONS, SIZES
from nlosplan.errors import UserError

__all__ = ["DENALI_CLASSES", "DENALI_SIZE_NAMES", "LIGHT_NAMES", "TEST_SIZE", "SEED", "capture_order",
           "class_name", "denali_split", "folder_name", "protocol_labels", "table1", "task_labels"]

#: DENALI's data names of the objects whose nlosplan (mesh) names differ.
_CLASS_NAMES = {"semicircle": "halfcircle"}
#: DENALI's 30 class names in its class order (sorted, as ``LabelEncoder``).
DENALI_CLASSES: tuple[str, ...] = tuple(sorted(_CLASS_NAMES.get(o, o) for o in DENALI_OBJECTS))
#: Size names in DENALI's folders and labels.
DENALI_SIZE_NAMES = {"4in": "4inch", "8in": "8inch"}
#: Lighting names in DENALI's folders.
LIGHT_NAMES = {"on": "lighton", "off": "lightoff"}
#: DENALI's split: test fraction and seed (``random_state``); also the seed of its training.
TEST_SIZE = 0.3
SEED = 42


def class_name(obj: str) -> str:
    """DENALI's label of an nlosplan object name (``"semicircle"`` -> ``"halfcircle"``; others unchanged)."""
    return _CLASS_NAMES.get(obj, obj)


def folder_name(obj: str, size: str, zones: str, lights: str) -> str:
    """DENALI's capture folder, e.g. ``folder_name("semicircle", "4in", "3x3", "on")`` ->
    ``"halfcircle_4inch_3x3_lighton_NLOSdata"``."""
    return f"{class_name(obj)}_{DENALI_SIZE_NAMES[size]}_{zones}_{LIGHT_NAMES[lights]}_NLOSdata"


def capture_order(labels: pd.DataFrame) -> np.ndarray:
    """Row indices that put captures in DENALI's query order.

    Parameters
    ----------
    labels : pandas.DataFrame
        One row per capture with ``object`` (nlosplan names), ``size`` (``"4in"``/``"8in"``), ``zones``
        (``"3x3"``), ``lights`` (``"on"``/``"off"``), ``position`` and ``repeat``.

    Returns
    -------
    ndarray of int, shape (N,)
        ``labels.iloc[order]`` is sorted by folder name (as strings), then position, then repeat.

    Raises
    ------
    UserError
        A missing column, a lighting or size DENALI does not have, or two rows with the same
        (folder, position, repeat).
    """
    need = ("object", "size", "zones", "lights", "position", "repeat")
    missing = [c for c in need if c not in labels.columns]
    if missing:
        raise UserError(f"captures need the label column(s) {', '.join(missing)} to be put in DENALI's order")
    bad = sorted(set(labels["lights"].astype(str)) - set(LIGHT_NAMES)) + sorted(
        set(labels["size"].astype(str)) - set(DENALI_SIZE_NAMES))
    if bad:
        raise UserError(f"captures labelled {', '.join(bad)} have no DENALI folder name (lights on/off, sizes "
                        "4in/8in)")
    cols = (labels[c].astype(str).tolist() for c in ("object", "size", "zones", "lights"))
    folders = [folder_name(o, s, z, li) for o, s, z, li in zip(*cols)]
    keys = pd.DataFrame({"folder": folders, "position": labels["position"].astype(int).to_numpy(),
                         "repeat": labels["repeat"].astype(int).to_numpy()})
    if keys.duplicated().any():
        raise UserError("two captures share folder, position and repeat; DENALI's order needs each once "
                        "(filter the store to one sensor, seed and variant)")
    return keys.sort_values(["folder", "position", "repeat"], kind="stable").index.to_numpy()


def protocol_labels(*, objects=DENALI_OBJECTS, sizes=SIZES, positions=range(N_POSITIONS), lights=("on", "off"),
                    repeats: int = 3, zones: str = "3x3") -> pd.DataFrame:
    """The labels of DENALI's protocol captures, in DENALI's order, without any data.

    With the defaults: the 36,000 rows of DENALI's real set (30 objects, 2 sizes, 100 positions,
    2 lightings, 3 repeats). Columns ``object`` (nlosplan names), ``size``, ``zones``, ``lights``,
    ``position``, ``repeat``, ``x``, ``y`` (DENALI's localization labels, metres).
    """
    from nlosplan.denali import positions_xy

    xy = positions_xy()
    rows = [(o, s, zones, li, int(p), r) for o in objects for s in sizes for li in lights for p in positions
            for r in range(int(repeats))]
    lab = pd.DataFrame(rows, columns=["object", "size", "zones", "lights", "position", "repeat"])
    lab = lab.iloc[capture_order(lab)].reset_index(drop=True)
    lab["x"], lab["y"] = xy[lab["position"], 0], xy[lab["position"], 1]
    return lab


def task_labels(labels: pd.DataFrame, task: str) -> np.ndarray:
    """DENALI's targets of ``task`` for captures: (N, 2) float (x, y) metres for ``"loc"``, else (N,) label names.

    ``"shape"``: DENALI's object names (``halfcircle``, ...); ``"size"``: ``"4inch"``/``"8inch"``.
    """
    if task == "loc":
        xy = labels[["x", "y"]].to_numpy(dtype=np.float64)
        if not np.isfinite(xy).all():
            raise UserError("localization needs x, y labels on every capture")
        return xy
    if task == "shape":
        return np.array([class_name(o) for o in labels["object"].astype(str).tolist()], dtype=object)
    if task == "size":
        return np.array([DENALI_SIZE_NAMES[s] for s in labels["size"].astype(str).tolist()], dtype=object)
    raise UserError(f"unknown task {task!r}; allowed: loc, shape, size")


def denali_split(task: str, targets, *, seed: int = SEED, test_size: float = TEST_SIZE) -> tuple[np.ndarray, np.ndarray]:
    """DENALI's 70/30 split of captures in DENALI's order.

    Parameters
    ----------
    task : {"loc", "shape", "size"}
        Localization: a shuffled split; classes: stratified on ``targets``.
    targets : array_like
        (N, 2) for ``"loc"`` (only its length is used), (N,) label names otherwise.
    seed : int
        scikit-learn's ``random_state`` (DENALI: 42).
    test_size : float

    Returns
    -------
    train, test : ndarray of int
        Row indices in scikit-learn's order (DENALI keeps it: its test predictions are stored in the
        test order, its training loader shuffles positions of the training list).

    Raises
    ------
    UserError
        Too few rows, or a class too small to stratify.
    """
    from sklearn.model_selection import train_test_split

    y = np.asarray(targets)
    idx = np.arange(len(y))
    if task != "loc":
        y = y.astype(str)  # as DENALI's list of names
    try:
        if task == "loc":
            return tuple(train_test_split(idx, test_size=test_size, shuffle=True, random_state=seed))
        return tuple(train_test_split(idx, test_size=test_size, stratify=y, random_state=seed))
    except ValueError as exc:
        raise UserError(f"DENALI's split of {len(y)} captures for {task!r} failed: {exc}") from None


@lru_cache(maxsize=1)
def table1() -> dict:
    """DENALI's published Table 1 (overall rows, real captures), shipped as package data.

    Returns
    -------
    dict
        ``source`` (the paper and repository), ``chance`` and ``values``: ``{task: {model: {metric: value}}}``
        with tasks ``loc`` (``loc_rmse``, ``mae``, metres), ``shape`` (``top1_acc``, ``top5_acc``,
        ``macro_f1``) and ``size`` (``top1_acc``), models ``mlp``, ``cnn1d``, ``cnn3d``, ``transformer``.
    """
    text = resources.files("nlosplan.tasks").joinpath("data", "denali_table1.json").read_text(encoding="utf-8")
    return json.loads(text)
