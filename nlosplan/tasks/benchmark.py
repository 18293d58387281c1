"""The DENALI benchmark table: one model per (architecture, task), trained, tested and broken down.

:func:`run_benchmark` trains every requested model on every requested task
on one split of a :class:`~nlosplan.data.dataset.Dataset`, evaluates the
metrics and breakdowns of :mod:`nlosplan.tasks.metrics` on the test rows and
records each model's training time. The result is tidy (one row per model,
task, metric and group) so that pandas pivots it into the paper's layout
(:mod:`nlosplan.reports.benchmark_table` does).

Settings ("profiles")
---------------------
``"cpu"`` (default)
    Every model at lr 1e-3 (the Transformer 3e-4), batch 64, log1p + z-score,
    at most ``epochs`` epochs with early stopping on a validation part of the
    training set. Chosen so that the table can be made on a laptop CPU.
``"denali"``
    DENALI's per-entry learning rate, batch size, epochs and preprocessing
    (:data:`~nlosplan.tasks.training.DENALI_CELLS`); ``epochs`` caps them.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass, replace
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from nlosplan.errors import UserError
from nlosplan.data.dataset import Dataset
from nlosplan.tasks.metrics import BREAKDOWNS, breakdown_rows, position_quadrants
from nlosplan.tasks.models import MODEL_NAMES, TASK_LABEL, TASKS, check_names, n_parameters
from nlosplan.tasks.splits import SPLITS, Split, make_split, split_applies
from nlosplan.tasks.training import TrainConfig, save_checkpoint, train_model

__all__ = ["DENALI_CELLS", "DEFAULT_EPOCHS", "DEFAULT_PATIENCE", "DEFAULT_WIDTH", "PROFILES", "SMALL", "TaskData",
           "denali_config", "run_benchmark", "task_classes", "task_data", "train_config"]

from nlosplan.tasks.names import (  # noqa: E402,F401 (re-exported)
    DEFAULT_EPOCHS, DEFAULT_PATIENCE, DEFAULT_WIDTH, PROFILES, SMALL,
)


#: DENALI's per-entry training settings (``benchmark/main_table/cells.py``):
#: (model, task) -> (lr, epochs, batch size, log1p + z-score).
DENALI_CELLS: dict[tuple[str, str], tuple[float, int, int, bool]] = {
    ("mlp", "loc"): (1e-3, 60, 64, False), ("cnn1d", "loc"): (1e-3, 60, 64, False),
    ("cnn3d", "loc"): (1e-3, 75, 64, False), ("transformer", "loc"): (1e-4, 75, 64, False),
    ("mlp", "shape"): (1e-5, 100, 256, True), ("cnn1d", "shape"): (1e-3, 100, 64, False),
    ("cnn3d", "shape"): (1e-3, 200, 256, True), ("transformer", "shape"): (1e-5, 50, 256, True),
    ("mlp", "size"): (1e-3, 75, 64, False), ("cnn1d", "size"): (1e-3, 100, 64, False),
    ("cnn3d", "size"): (1e-3, 75, 64, False), ("transformer", "size"): (1e-4, 10, 256, True),
}


def denali_config(model: str, task: str, **overrides) -> TrainConfig:
    """DENALI's learning rate, epochs, batch size and preprocessing for one table entry.

    Parameters
    ----------
    model, task : str
        As :func:`nlosplan.tasks.models.build_model`.
    **overrides
        Any :class:`TrainConfig` field.
    """
    if (model, task) not in DENALI_CELLS:
        raise UserError(f"no DENALI setting for model {model!r} and task {task!r}")
    lr, epochs, batch, log = DENALI_CELLS[(model, task)]
    base = TrainConfig(lr=lr, max_epochs=epochs, batch_size=batch, log_transform=log, normalize=log)
    return replace(base, **overrides)


def train_config(model: str, task: str, *, profile: str = "cpu", epochs: int | None = None,
                 patience: int | None = DEFAULT_PATIENCE, seed: int = 42,
                 max_seconds: float | None = None) -> TrainConfig:
    """The training settings of one table entry.

    Parameters
    ----------
    model, task : str
    profile : {"cpu", "denali"}
        See the module notes.
    epochs : int, optional
        Epoch cap (default :data:`DEFAULT_EPOCHS` for ``"cpu"``, DENALI's for ``"denali"``).
    patience : int or None
        Early-stopping patience in epochs (None: train every epoch; the best
        validation epoch is still kept).
    seed : int
    max_seconds : float, optional
        Wall-clock budget of this entry.
    """
    if profile not in PROFILES:
        raise UserError(f"unknown profile {profile!r}; allowed: {', '.join(PROFILES)}")
    if epochs is not None and epochs < 1:
        raise UserError(f"epochs={epochs} must be >= 1")
    common = dict(patience=patience, seed=seed, max_seconds=max_seconds)
    if profile == "denali":
        cfg = denali_config(model, task, **common)
        return replace(cfg, max_epochs=min(cfg.max_epochs, epochs)) if epochs else cfg
    lr = 3e-4 if model == "transformer" else 1e-3
    return TrainConfig(lr=lr, batch_size=64, max_epochs=epochs or DEFAULT_EPOCHS, **common)


def _quadrants(labels) -> np.ndarray:
    """Near/far quadrant of every row (over the whole dataset); "" where x, y are unknown."""
    out = np.full(len(labels), "", dtype=object)
    ok = np.isfinite(labels[["x", "y"]].to_numpy(dtype=np.float64)).all(axis=1)
    if ok.sum() >= 4:
        out[ok] = position_quadrants(labels[ok])["quadrant"].to_numpy()
    return out


def _targets(ds: Dataset, task: str, classes) -> np.ndarray:
    if task == "loc":
        xy = ds.labels[["x", "y"]].to_numpy(dtype=np.float64)
        if not np.isfinite(xy).all():
            raise UserError(f"localization needs x, y labels; {int((~np.isfinite(xy).all(axis=1)).sum())} rows "
                            "have none (filter them out, e.g. by source)")
        return xy
    lookup = {c: i for i, c in enumerate(classes)}
    return np.array([lookup[v] for v in ds.labels[TASK_LABEL[task]].astype(str)], dtype=np.int64)


def task_classes(ds: Dataset, task: str) -> tuple[str, ...] | None:
    """Class names of a classification task in ``ds``, sorted (the models' output order); None for ``"loc"``."""
    return None if task == "loc" else tuple(sorted(ds.labels[TASK_LABEL[task]].astype(str).unique()))


@dataclass(frozen=True, eq=False)
class TaskData:
    """One task's train and test rows and their targets.

    Attributes
    ----------
    train, test : Dataset
    y_train : ndarray
        (N, 2) x, y in metres for ``"loc"``; class names (N,) otherwise.
    y_test : ndarray
        (M, 2) x, y in metres for ``"loc"``; class indices (M,) otherwise.
    split : Split
    """

    train: Dataset
    test: Dataset
    y_train: np.ndarray
    y_test: np.ndarray
    split: Split


def task_data(ds: Dataset, task: str, split: str, *, seed: int, test_size: float = 0.3,
              classes: tuple[str, ...] | None = None) -> TaskData:
    """Split ``ds`` for one task and take its targets (the benchmark's data, also the design evaluator's).

    Parameters
    ----------
    ds : Dataset
    task : {"loc", "shape", "size"}
    split : str
        One of :data:`~nlosplan.tasks.splits.SPLITS` that applies to ``task``.
    seed : int
    test_size : float
    classes : tuple of str, optional
        The task's classes (:func:`task_classes` of the whole dataset).

    Raises
    ------
    UserError
        The split leaves fewer than 2 training or no test rows, or localization rows without x, y.
    """
    sp = make_split(ds, split, task, seed=seed, test_size=test_size)
    if len(sp.train) < 2 or len(sp.test) < 1:
        raise UserError(f"split {split!r} leaves {len(sp.train)} training and {len(sp.test)} test rows")
    train, test = ds.take(sp.train), ds.take(sp.test)
    y_train = (_targets(train, task, classes) if task == "loc"
               else train.labels[TASK_LABEL[task]].astype(str).to_numpy())
    return TaskData(train, test, y_train, _targets(test, task, classes), sp)


def run_benchmark(dataset: Dataset, *, models: Sequence[str] = MODEL_NAMES, tasks: Sequence[str] = TASKS,
                  split: str = "random", seed: int = 42, epochs: int | None = None, width: float = DEFAULT_WIDTH,
                  average_repeats: bool = True, profile: str = "cpu", patience: int | None = DEFAULT_PATIENCE,
                  max_seconds: float | None = None, test_size: float = 0.3, checkpoint_dir=None,
                  progress: Callable[[dict], None] | None = None) -> dict:
    """Train and evaluate the benchmark table.

    Parameters
    ----------
    dataset : Dataset
        Captures with labels (object, size, class_group, position, x, y).
    models : sequence of str
        Among ``"mlp"``, ``"cnn1d"``, ``"cnn3d"``, ``"transformer"``.
    tasks : sequence of str
        Among ``"loc"``, ``"shape"``, ``"size"``.
    split : str
        One of :data:`nlosplan.tasks.splits.SPLITS`. A split that does not
        apply to a task (held-out objects for shape, held-out sizes for size)
        gives that task's entries status ``"n/a"``.
    seed : int
        Seed of the split, the validation part, initialisation and batch order.
    epochs : int, optional
        Epoch cap (see :func:`train_config`).
    width : float
        Model size factor (1 = the paper's; see the measured timings in the README).
    average_repeats : bool
        Average each scene's repeats first (DENALI averages the 3x3 repeats).
    profile : {"cpu", "denali"}
        Training settings (:func:`train_config`).
    patience : int or None
        Early-stopping patience, epochs.
    max_seconds : float, optional
        Wall-clock budget per entry.
    test_size : float
        Test fraction (rows, positions or object classes).
    checkpoint_dir : path, optional
        Write each trained model there as ``{model}_{task}.pt``.
    progress : callable, optional
        Called with dicts: ``{"event": "start", "model", "task", "index", "total"}``,
        ``{"event": "epoch", ..., "record": {...}}``, ``{"event": "done", ...}``.

    Returns
    -------
    dict
        ``rows``: list of {model, task, metric, group_by, group, value, n};
        ``runs``: one dict per (model, task) with ``status`` ("ok" or "n/a"),
        ``reason``, ``train_seconds``, ``seconds_per_epoch``, ``epochs_run``,
        ``best_epoch``, ``stopped``, ``n_train``, ``n_val``, ``n_test``,
        ``n_params`` and the training settings; ``config``: the inputs, data
        shape, versions and torch threads; ``seconds``: total wall time.
    """
    import torch

    from nlosplan import __version__

    t0 = time.perf_counter()
    models = check_names("model(s)", models, MODEL_NAMES)
    tasks = check_names("task(s)", tasks, TASKS)
    if split not in SPLITS:
        raise UserError(f"unknown split {split!r}; allowed: {', '.join(SPLITS)}")
    if not width > 0:
        raise UserError(f"width={width} must be > 0")
    train_config(models[0], tasks[0], profile=profile, epochs=epochs, patience=patience)  # check settings early
    if len(dataset) == 0:
        raise UserError("the dataset is empty")
    ds = dataset.mean_over_repeats() if average_repeats else dataset
    need_quadrant = any(c == "quadrant" for t in tasks for c, _ in BREAKDOWNS[t])
    quadrant = _quadrants(ds.labels) if need_quadrant else None
    classes = {t: task_classes(ds, t) for t in tasks if t != "loc"}
    for t, names in classes.items():
        if len(names) < 2:
            raise UserError(f"task {t!r} needs at least 2 classes of {TASK_LABEL[t]}; the dataset has {', '.join(names)}")
    rows: list[dict] = []
    runs: list[dict] = []
    total = len(models) * len(tasks)
    say = progress or (lambda _event: None)
    for ti, task in enumerate(tasks):
        why = split_applies(split, task)
        if not why:  # the same data for every model of this task
            data = task_data(ds, task, split, seed=seed, test_size=test_size, classes=classes.get(task))
            train, test, y_train, y_test, sp = data.train, data.test, data.y_train, data.y_test, data.split
            q_test = None if quadrant is None else quadrant[sp.test]
        for mi, model in enumerate(models):
            index = ti * len(models) + mi
            base = {"model": model, "task": task, "split": split}
            if why:
                runs.append({**base, "status": "n/a", "reason": why})
                say({"event": "done", **base, "index": index, "total": total})
                continue
            cfg = train_config(model, task, profile=profile, epochs=epochs, patience=patience, seed=seed,
                               max_seconds=max_seconds)
            say({"event": "start", **base, "index": index, "total": total})
            trained = train_model(train.histograms, y_train, model=model, task=task, config=cfg, width=width,
                                  classes=classes.get(task),
                                  progress=lambda rec, b=base, i=index: say({"event": "epoch", **b, "index": i,
                                                                             "total": total, "record": rec}))
            t_eval = time.perf_counter()
            scores = trained.predict(test.histograms)
            for r in breakdown_rows(task, test.labels, scores, y_test, quadrant=q_test):
                rows.append({"model": model, "task": task, **r})
            n_epochs = len(trained.history)
            runs.append({**base, "status": "ok", "reason": "", "train_seconds": trained.train_seconds,
                         "seconds_per_epoch": trained.train_seconds / max(n_epochs, 1),
                         "eval_seconds": time.perf_counter() - t_eval, "epochs_run": n_epochs,
                         "best_epoch": trained.best_epoch, "stopped": trained.stopped, "n_train": trained.n_train,
                         "n_val": trained.n_val, "n_test": int(len(sp.test)), "n_params": n_parameters(trained.model),
                         "width": width, "split_info": sp.info, **{k: v for k, v in asdict(cfg).items()
                                                                  if k not in ("seed",)}})
            if checkpoint_dir is not None:
                save_checkpoint(Path(checkpoint_dir) / f"{model}_{task}.pt", trained)
            say({"event": "done", **base, "index": index, "total": total})
    config = {"models": models, "tasks": tasks, "split": split, "seed": seed, "epochs": epochs, "width": width,
              "average_repeats": average_repeats, "profile": profile, "patience": patience,
              "max_seconds": max_seconds, "test_size": test_size, "n_rows": len(ds), "n_rows_given": len(dataset),
              "histogram_shape": list(ds.histograms.shape[1:]), "bin_width_ps": ds.bin_width_ps,
              "sources": sorted(ds.labels["source"].astype(str).unique().tolist()),
              "n_classes": {t: len(c) for t, c in classes.items()},
              "versions": {"nlosplan": __version__, "torch": torch.__version__}, "torch_threads": torch.get_num_threads()}
    return {"rows": rows, "runs": runs, "config": config, "seconds": time.perf_counter() - t0}
