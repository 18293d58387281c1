"""DENALI's training recipe, exactly: one benchmark cell (model x task) trained and scored as DENALI did.

One implementation, shared by ``nlosplan bench denali`` (:mod:`nlosplan.tasks.denali_bench`) and any learner
that must be DENALI's. Facts from DENALI's repository (github.com/NikhilBehari/denali @ 9e10832,
``benchmark/main_table``: ``cells.py``, ``training.py``, ``data.py``, ``models.py``; MIT), read, not copied:

- **Models**: the 1D CNN (:class:`~nlosplan.tasks.models.CNN1D` at width 1: DENALI's ``MediumConv1DNet``,
  for localization its ``MediumConv1DNetReg`` head) and the MLP (:class:`~nlosplan.tasks.models.MLP`,
  ``SmallMLP``), with DENALI's layer names (its checkpoints load into them with ``strict=True``).
  Initialised in DENALI's order: its first layer is lazy, so it draws its weights last, after the rest of
  the model, on the training device.
- **Cells** (:data:`~nlosplan.tasks.benchmark.DENALI_CELLS`): learning rate, epochs, batch size and input per
  (model, task); raw counts (float32) everywhere but the shape MLP, which takes ``log1p(clip(x, 0))``
  z-scored with one mean and standard deviation over *all* captures (train and test, as DENALI).
- **Training**: torch's generator seeded with 42; Adam (betas 0.9/0.999, eps 1e-8, no weight decay);
  cross-entropy for classes, ``MSELoss(reduction="sum")`` on raw metres for localization; a ``DataLoader``
  that shuffles the training rows every epoch and one that reads the test rows in order (both draw from
  torch's generator as DENALI's do, so a CPU run follows DENALI's code draw for draw); the test set is
  scored after every epoch.
- **Split**: :func:`~nlosplan.tasks.denali_protocol.denali_split` (70/30, seed 42, stratified for classes).
- **Reported**: DENALI keeps the epoch with the best *test* top-1 (classes) or test MAE (localization) and
  reports its metric (top-1; for localization DENALI's RMSE, :func:`~nlosplan.tasks.metrics.loc_rmse`).

Test-blind numbers (the choice made here)
-----------------------------------------
DENALI's best-on-test epoch looks at the test set. Two numbers that do not:

- ``predicted_last_epoch``: the same run's last epoch (the recipe's fixed epoch count), so the headline
  stays DENALI's exact protocol on DENALI's full training set and the test-blind figure costs nothing;
- ``predicted_validation_epoch`` (``validation=True`` only): a *separate* run that trains on the training
  rows minus a seeded tenth (stratified for classes: 90 % of DENALI's training set), scores that tenth and
  the test set after every epoch, picks the epoch by DENALI's criterion on the tenth and reports the test
  metric there. Its own best-on-test and last-epoch figures are kept too (its ``predicted`` is on 90 %
  of the training set, never the headline).

Randomness and devices: torch's global generator is forked (the caller's state is restored), numpy's and
Python's are not used; on the CPU a run is deterministic for a seed and thread count. ``device`` ``"cuda"``
runs on the GPU with cuDNN's deterministic algorithms, as DENALI.
"""

from __future__ import annotations

import contextlib
import time
from typing import Callable

import numpy as np
import torch
from torch import nn

from nlosplan.errors import UserError
from nlosplan.tasks.benchmark import DENALI_CELLS
from nlosplan.tasks.denali_protocol import SEED, denali_split
from nlosplan.tasks.denali_result import CellResult
from nlosplan.tasks.metrics import classification_metrics, regression_metrics
from nlosplan.tasks.models import CNN1D, MLP

__all__ = ["RECIPE_MODELS", "VALIDATION_FRACTION", "CellResult", "cell_settings", "denali_model", "resolve_device",
           "train_denali_cell"]

#: The models of DENALI's recipe implemented here (its MLP and 1D CNN cells).
RECIPE_MODELS = ("mlp", "cnn1d")
#: Share of the training rows held out in ``validation=True`` runs.
VALIDATION_FRACTION = 0.1
#: What each task reports, and how DENALI picks its epoch: (metric, selection metric, higher is better).
_METRICS = {"loc": ("loc_rmse", "mae", False), "shape": ("top1_acc", "top1_acc", True),
            "size": ("top1_acc", "top1_acc", True)}


def cell_settings(model: str, task: str) -> dict:
    """DENALI's settings of one cell: ``lr``, ``epochs``, ``batch_size``, ``log_zscore`` (bool)."""
    if model not in RECIPE_MODELS or task not in _METRICS:
        raise UserError(f"DENALI's recipe has no cell {model!r} x {task!r}; models {', '.join(RECIPE_MODELS)}, "
                        f"tasks {', '.join(_METRICS)}")
    lr, epochs, batch, log = DENALI_CELLS[(model, task)]
    return {"lr": lr, "epochs": epochs, "batch_size": batch, "log_zscore": log}


def resolve_device(device: str) -> str:
    """``"auto"`` -> ``"cuda"`` when torch sees a GPU, else ``"cpu"``; ``"cuda"`` without one is a UserError."""
    if device == "auto":
        return "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cpu":
        return "cpu"
    if device == "cuda" or (device.startswith("cuda:") and device[5:].isdigit()):
        if not torch.cuda.is_available():
            raise UserError(f"--device {device}: torch sees no CUDA GPU on this machine (torch {torch.__version__}); "
                            "use --device cpu or auto")
        n = torch.cuda.device_count()
        if device != "cuda" and int(device[5:]) >= n:
            raise UserError(f"--device {device}: torch sees {n} GPU(s), cuda:0 to cuda:{n - 1}")
        return device
    raise UserError(f"unknown device {device!r}; allowed: auto, cpu, cuda, cuda:N")


def denali_model(model: str, task: str, input_shape, n_outputs: int) -> nn.Module:
    """DENALI's network of a cell (width 1, dropout 0.1), initialised from torch's global generator.

    Parameters
    ----------
    model : {"mlp", "cnn1d"}
    task : {"loc", "shape", "size"}
        ``"loc"`` gives the 1D CNN DENALI's regressor head (``mlp``, ``out_linear``, ``out_tanh``).
    input_shape : tuple of int
        ``(rows, cols, bins)``; DENALI's lazy first layers take any.
    n_outputs : int
    """
    rows, cols, bins = (int(v) for v in input_shape)
    if model == "cnn1d":
        return CNN1D(rows * cols, n_outputs, denali_regressor=task == "loc")
    if model == "mlp":
        return MLP(rows * cols * bins, n_outputs)
    raise UserError(f"DENALI's recipe has no model {model!r}; allowed: {', '.join(RECIPE_MODELS)}")


def _denali_init(net: nn.Module, seed: int, device: str) -> nn.Module:
    """Re-draw the weights in DENALI's order (its lazy first layer last, on ``device``) from ``seed``."""
    torch.manual_seed(seed)
    first = net.conv1 if isinstance(net, CNN1D) else net.fc1
    for m in net.modules():
        if m is not first and isinstance(m, (nn.Conv1d, nn.Linear)):
            m.reset_parameters()
    net.to(device)
    first.reset_parameters()
    return net


class _Rows(torch.utils.data.Dataset):
    """Rows of (inputs, targets) tensors by batches of positions in ``rows`` (what DENALI's Subset serves)."""

    def __init__(self, x: torch.Tensor, y: torch.Tensor, rows: np.ndarray):
        self.x, self.y, self.rows = x, y, torch.as_tensor(np.asarray(rows, dtype=np.int64))

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, positions):
        r = self.rows[torch.as_tensor(positions, dtype=torch.int64)].to(self.x.device)
        return self.x[r], self.y[r]


def _loader(x, y, rows, batch: int, shuffle: bool) -> torch.utils.data.DataLoader:
    """A DataLoader drawing from torch's generator as DENALI's (a base seed per pass; the shuffle's seed)."""
    data = _Rows(x, y, rows)
    order = (torch.utils.data.RandomSampler(range(len(data))) if shuffle
             else torch.utils.data.SequentialSampler(range(len(data))))
    return torch.utils.data.DataLoader(data, sampler=torch.utils.data.BatchSampler(order, batch, drop_last=False),
                                       batch_size=None, collate_fn=lambda b: b)


def _outputs(net: nn.Module, loader) -> np.ndarray:
    net.eval()
    out = []
    with torch.inference_mode():
        for xb, _ in loader:
            out.append(net(xb).float().cpu())
    return torch.cat(out).numpy()


def _score(task: str, outputs: np.ndarray, targets: np.ndarray) -> dict:
    if task == "loc":
        m = regression_metrics(outputs, targets)
        return {k: m[k] for k in ("loc_rmse", "mae", "mse")}
    m = classification_metrics(outputs, targets)
    return {k: m[k] for k in ("top1_acc", "top5_acc", "macro_f1")}


def _predictions(task: str, outputs: np.ndarray) -> np.ndarray:
    return outputs.astype(np.float64) if task == "loc" else outputs.argmax(axis=1)


@contextlib.contextmanager
def _torch_state(device: str):
    """Fork torch's generators (CPU, and the GPU in use) and pin cuDNN to deterministic algorithms; restore both."""
    devices = [torch.device(device).index or 0] if device.startswith("cuda") else []
    cudnn = torch.backends.cudnn
    before = (cudnn.deterministic, cudnn.benchmark)
    with torch.random.fork_rng(devices=devices):
        cudnn.deterministic, cudnn.benchmark = True, False
        try:
            yield
        finally:
            cudnn.deterministic, cudnn.benchmark = before


def _prepare(histograms, log_zscore: bool) -> tuple[np.ndarray, dict]:
    """DENALI's ``apply_histogram_transform`` over all rows: float32, optionally log1p + one z-score."""
    x = np.asarray(histograms, dtype=np.float32)
    if not log_zscore:
        return x, {"input": "raw counts"}
    x = np.log1p(np.clip(x, 0.0, None))
    mean, std = float(x.mean()), float(x.std() + 1e-6)
    x = ((x - mean) / std).astype(np.float32, copy=False)
    return x, {"input": "log1p(clip(x, 0)) z-scored over all captures", "mean": mean, "std": std}


def _check_inputs(histograms, targets, task, model, train_index, test_index):
    x = np.asarray(histograms)
    if x.ndim != 4 or len(x) < 2:
        raise UserError(f"histograms must be (N >= 2, rows, cols, bins), got {x.shape}")
    settings = cell_settings(model, task)
    if task == "loc":
        try:
            y = np.asarray(targets, dtype=np.float64)
        except (TypeError, ValueError):
            raise UserError("localization targets must be finite (N, 2) x, y in metres, not names") from None
        if y.shape != (len(x), 2) or not np.isfinite(y).all():
            raise UserError(f"localization targets must be finite (N, 2) x, y in metres, got {y.shape}")
        classes = None
    else:
        y = np.asarray(targets).astype(str)
        if y.shape != (len(x),):
            raise UserError(f"class targets must be (N,) names, got {y.shape}")
        classes = tuple(sorted(set(y)))
        if len(classes) < 2:
            raise UserError(f"classification needs at least 2 classes, got {', '.join(classes)}")
    if (train_index is None) != (test_index is None):
        raise UserError("give both train_index and test_index, or neither (DENALI's split)")
    if train_index is None:
        train_index, test_index = denali_split(task, y)
    train_index, test_index = (np.asarray(i, dtype=np.int64) for i in (train_index, test_index))
    for name, idx in (("train_index", train_index), ("test_index", test_index)):
        if idx.ndim != 1 or len(idx) < 1 or idx.min() < 0 or idx.max() >= len(x):
            raise UserError(f"{name} must be a non-empty list of rows 0 to {len(x) - 1}")
    if np.intersect1d(train_index, test_index).size:
        raise UserError("train_index and test_index share rows")
    return x, y, classes, settings, train_index, test_index


def _validation_rows(train_index: np.ndarray, y: np.ndarray, task: str, seed: int) -> tuple[np.ndarray, np.ndarray]:
    from sklearn.model_selection import train_test_split

    n_val = max(1, int(round(VALIDATION_FRACTION * len(train_index))))
    if len(train_index) - n_val < 1:
        raise UserError(f"{len(train_index)} training rows leave none to train on after the validation tenth")
    strat = None
    if task != "loc":
        _, counts = np.unique(y[train_index], return_counts=True)
        if counts.min() >= 2 and n_val >= len(counts) and len(train_index) - n_val >= len(counts):
            strat = y[train_index]
    fit, val = train_test_split(train_index, test_size=n_val, stratify=strat, random_state=seed)
    return np.asarray(fit), np.asarray(val)


def train_denali_cell(histograms, targets, task: str, model: str, *, epochs: int | None = None,
                      device: str = "cpu", validation: bool = False, seed: int = SEED, train_index=None,
                      test_index=None, progress: Callable[[dict], None] | None = None) -> CellResult:
    """Train and score one cell of DENALI's benchmark with DENALI's recipe (see the module notes).

    Parameters
    ----------
    histograms : array_like, shape (N, rows, cols, bins)
        Raw counts of every capture, train and test (the shape MLP's z-score uses all of them, as DENALI).
        Put in DENALI's order (:func:`~nlosplan.tasks.denali_protocol.capture_order`) for DENALI's split.
    targets : array_like
        (N, 2) x, y in metres for ``task="loc"``; (N,) label names otherwise
        (:func:`~nlosplan.tasks.denali_protocol.task_labels`).
    task : {"loc", "shape", "size"}
    model : {"mlp", "cnn1d"}
    epochs : int, optional
        Epochs to run (default: the cell's, DENALI's 60, 75 or 100).
    device : {"cpu", "cuda", "cuda:N", "auto"}
    validation : bool
        Train on the training rows minus a seeded tenth and pick an epoch on that tenth as well
        (``mode="validation"``; see the module notes).
    seed : int
        Seed of torch's generator and of the validation tenth (DENALI: 42). The split's seed stays DENALI's
        unless ``train_index``/``test_index`` are given.
    train_index, test_index : array_like of int, optional
        Rows to train on and to score (default DENALI's split of ``targets``).
    progress : callable, optional
        Called after each epoch with its history record plus ``task``, ``model``, ``mode``, ``epochs``.

    Returns
    -------
    CellResult

    Raises
    ------
    UserError
        A cell DENALI has no recipe for, bad shapes, too few rows or classes, an unavailable device.

    Examples
    --------
    >>> res = train_denali_cell(hist, labels, "size", "cnn1d", epochs=5)   # doctest: +SKIP
    >>> res.predicted, res.best_epoch, res.predicted_last_epoch             # doctest: +SKIP
    """
    t0 = time.perf_counter()
    x_raw, y, classes, cfg, train_index, test_index = _check_inputs(histograms, targets, task, model, train_index,
                                                                    test_index)
    run_epochs = cfg["epochs"] if epochs is None else int(epochs)
    if run_epochs < 1:
        raise UserError(f"epochs={epochs} must be >= 1")
    dev = resolve_device(device)
    metric, selection, higher = _METRICS[task]
    fit, val = (_validation_rows(train_index, y, task, seed) if validation else (train_index, train_index[:0]))
    x_np, prep = _prepare(x_raw, cfg["log_zscore"])
    if task == "loc":
        y_t, targets_np = torch.from_numpy(y.astype(np.float32)), y
    else:
        lookup = {c: i for i, c in enumerate(classes)}
        targets_np = np.array([lookup[v] for v in y], dtype=np.int64)
        y_t = torch.from_numpy(targets_np)
    history: list[dict] = []
    better = (lambda a, b: a > b) if higher else (lambda a, b: a < b)
    with _torch_state(dev):
        torch.manual_seed(seed)
        net = _denali_init(denali_model(model, task, x_np.shape[1:], 2 if task == "loc" else len(classes)), seed,
                           dev)
        x_t, y_t = torch.from_numpy(x_np).to(dev), y_t.to(dev)
        del x_np
        batch = cfg["batch_size"]
        train_loader = _loader(x_t, y_t, fit, batch, shuffle=True)
        test_loader = _loader(x_t, y_t, test_index, batch, shuffle=False)
        val_loader = _loader(x_t, y_t, val, batch, shuffle=False) if len(val) else None
        opt = torch.optim.Adam(net.parameters(), lr=cfg["lr"], betas=(0.9, 0.999), eps=1e-8, weight_decay=0.0)
        loss_fn = nn.MSELoss(reduction="sum") if task == "loc" else nn.CrossEntropyLoss()
        best = {"test": (None, 0, None), "val": (None, 0, None)}  # (selection value, epoch, test predictions)
        for epoch in range(1, run_epochs + 1):
            net.train()
            total, batches = torch.zeros((), device=dev), 0
            for xb, yb in train_loader:
                opt.zero_grad()
                loss = loss_fn(net(xb), yb)
                loss.backward()
                opt.step()
                total += loss.detach()
                batches += 1
            out_test = _outputs(net, test_loader)
            test = _score(task, out_test, targets_np[test_index])
            valm = _score(task, _outputs(net, val_loader), targets_np[val]) if val_loader is not None else None
            record = {"epoch": epoch, "train_loss": float(total) / max(batches, 1), "test": test, "val": valm,
                      "seconds": time.perf_counter() - t0}
            history.append(record)
            pred = _predictions(task, out_test)
            for part, scores in (("test", test), ("val", valm)):
                if scores is not None and (best[part][0] is None or better(scores[selection], best[part][0])):
                    best[part] = (scores[selection], epoch, pred)
            if progress is not None:
                progress({**record, "task": task, "model": model, "mode": "validation" if validation else "denali",
                          "epochs": run_epochs})
    by_epoch = {r["epoch"]: r for r in history}
    predictions = {"best": best["test"][2], "last": pred}
    v_epoch = v_metric = None
    if validation:
        v_epoch = best["val"][1]
        v_metric = by_epoch[v_epoch]["test"][metric]
        predictions["validation"] = best["val"][2]
    return CellResult(
        task=task, model=model, metric=metric, selection=selection, mode="validation" if validation else "denali",
        predicted=by_epoch[best["test"][1]]["test"][metric], best_epoch=best["test"][1],
        predicted_last_epoch=history[-1]["test"][metric], epochs=run_epochs, predicted_validation_epoch=v_metric,
        validation_epoch=v_epoch, history=tuple(history), n_train=len(fit), n_val=len(val), n_test=len(test_index),
        test_index=test_index, predictions=predictions, classes=classes,
        settings={**cfg, "epochs_run": run_epochs}, preprocessing=prep, seconds=time.perf_counter() - t0,
        device=dev, seed=int(seed), torch_threads=torch.get_num_threads())
