"""Training of the benchmark models: preprocessing, seeded Adam with early stopping, checkpoints.

As DENALI (``benchmark/main_table/training.py``, ``data.py``): optional
``log1p(clip(x, 0))`` then a z-score with one scalar mean and standard
deviation; Adam (betas 0.9/0.999, eps 1e-8, no weight decay); cross-entropy
for classification, MSE for localization. Differences, on purpose:

- statistics come from the training rows only (DENALI uses all rows);
- the best epoch is chosen on a validation part of the training set
  (``val_fraction``, stratified for classification), never on the test set,
  with early stopping (``patience``) and the best weights restored;
- localization targets are standardized with training statistics
  (``standardize_targets``; DENALI regresses raw metres, which costs many
  epochs just to learn the 1 m offset) and the MSE is a mean, not a sum
  (Adam is invariant to that scale up to its eps);
- a wall-clock budget (``max_seconds``) besides ``max_epochs``.

Randomness: the model initialisation, dropout and the batch order come from
``seed`` only (torch's global generator is forked and restored, numpy's is
not touched). ``torch.set_num_threads`` is left to the caller; results are
reproducible for the same seed and thread count.
"""

from __future__ import annotations

import math
import time
from typing import Callable

import numpy as np
import torch
from sklearn.model_selection import train_test_split
from torch import nn

from nlosplan.errors import UserError
from nlosplan.tasks.checkpoints import CHECKPOINT_FORMAT, load_checkpoint, save_checkpoint
from nlosplan.tasks.models import ModelSpec, model_from_spec
from nlosplan.tasks.targets import encode_targets
from nlosplan.tasks.training_types import Preprocessing, TrainConfig, TrainedModel, apply_histogram_transform

__all__ = ["CHECKPOINT_FORMAT", "Preprocessing", "TrainConfig", "TrainedModel", "apply_histogram_transform",
           "load_checkpoint", "save_checkpoint", "train_model"]


def _validation_rows(n: int, labels, config: TrainConfig) -> tuple[np.ndarray, np.ndarray]:
    """(fit rows, validation rows) of the training set; stratified when every class allows it."""
    idx = np.arange(n)
    n_val = int(round(config.val_fraction * n))
    if config.val_fraction == 0 or n_val < 1 or n - n_val < 1:
        return idx, idx[:0]
    strat = None
    if labels is not None:
        _, counts = np.unique(labels, return_counts=True)
        if counts.min() >= 2 and n_val >= len(counts) and n - n_val >= len(counts):
            strat = labels
    fit, val = train_test_split(idx, test_size=n_val, stratify=strat, random_state=config.seed)
    return np.sort(fit), np.sort(val)


def _loss_on(model: nn.Module, loss_fn, x: torch.Tensor, y: torch.Tensor, batch: int = 1024) -> float:
    model.eval()
    total = 0.0
    with torch.inference_mode():
        for i in range(0, len(x), batch):
            total += float(loss_fn(model(x[i:i + batch]), y[i:i + batch])) * len(x[i:i + batch])
    return total / max(len(x), 1)


def train_model(histograms, targets, *, model: str, task: str, config: TrainConfig | None = None,
                width: float = 1.0, dropout: float = 0.1, classes=None,
                progress: Callable[[dict], None] | None = None) -> TrainedModel:
    """Train one benchmark model on a training set.

    Parameters
    ----------
    histograms : array_like, shape (N, rows, cols, bins)
        Raw counts of the training rows (preprocessing is fitted here).
    targets : array_like
        (N, 2) (x, y) in metres for ``task="loc"``; (N,) class labels (any
        hashable, stored as str) for ``"shape"`` and ``"size"``.
    model : {"mlp", "cnn1d", "cnn3d", "transformer"}
    task : {"loc", "shape", "size"}
    config : TrainConfig, optional
    width, dropout : float
        Model size factor and dropout (:func:`~nlosplan.tasks.models.build_model`).
    classes : sequence of str, optional
        Class names in output order (default: the sorted distinct training labels).
    progress : callable, optional
        Called with each epoch's history record.

    Returns
    -------
    TrainedModel

    Raises
    ------
    UserError
        Mismatched shapes, too few rows, a label outside ``classes``.
    """
    cfg = config or TrainConfig()
    t0 = time.perf_counter()
    x_raw = np.asarray(histograms, dtype=np.float32)
    if x_raw.ndim != 4 or len(x_raw) < 2:
        raise UserError(f"training histograms must be (N >= 2, rows, cols, bins), got {x_raw.shape}")
    y_np, names = encode_targets(task, targets, len(x_raw), classes)
    strat_labels = None if names is None else y_np
    fit, val = _validation_rows(len(x_raw), strat_labels, cfg)
    prep = Preprocessing.fit(x_raw[fit], log_transform=cfg.log_transform, normalize=cfg.normalize)
    x_all = torch.from_numpy(prep.apply(x_raw))
    t_mean = t_std = None
    if task == "loc":
        if cfg.standardize_targets:
            t_mean = tuple(float(v) for v in y_np[fit].mean(axis=0))
            t_std = tuple(float(max(v, 1e-9)) for v in y_np[fit].std(axis=0))
            y_np = (y_np - np.asarray(t_mean)) / np.asarray(t_std)
        y_all = torch.from_numpy(y_np.astype(np.float32))
        loss_fn: nn.Module = nn.MSELoss()
    else:
        y_all = torch.from_numpy(y_np)
        loss_fn = nn.CrossEntropyLoss()
    spec = ModelSpec(model, task, tuple(x_raw.shape[1:]), 2 if task == "loc" else len(names), float(width),
                     float(dropout))
    x_fit, y_fit = x_all[torch.from_numpy(fit)], y_all[torch.from_numpy(fit)]
    x_val, y_val = x_all[torch.from_numpy(val)], y_all[torch.from_numpy(val)]

    history: list[dict] = []
    stopped = "max_epochs"
    with torch.random.fork_rng(devices=[]):
        torch.manual_seed(cfg.seed)
        net = model_from_spec(spec)
        opt = torch.optim.Adam(net.parameters(), lr=cfg.lr, betas=(0.9, 0.999), eps=1e-8,
                               weight_decay=cfg.weight_decay)
        order = torch.Generator().manual_seed(cfg.seed)
        best_loss, best_state, best_epoch, waited = math.inf, None, 0, 0
        for epoch in range(1, cfg.max_epochs + 1):
            net.train()
            perm = torch.randperm(len(x_fit), generator=order)
            total, seen = 0.0, 0
            for i in range(0, len(perm), cfg.batch_size):
                b = perm[i:i + cfg.batch_size]
                opt.zero_grad(set_to_none=True)
                loss = loss_fn(net(x_fit[b]), y_fit[b])
                loss.backward()
                opt.step()
                total += float(loss.detach()) * len(b)
                seen += len(b)
                if cfg.max_seconds is not None and time.perf_counter() - t0 > cfg.max_seconds:
                    stopped = "time"
                    break
            val_loss = _loss_on(net, loss_fn, x_val, y_val) if len(val) else None
            record = {"epoch": epoch, "train_loss": total / max(seen, 1), "val_loss": val_loss,
                      "seconds": time.perf_counter() - t0}
            history.append(record)
            if progress is not None:
                progress(record)
            score = val_loss if val_loss is not None else -epoch  # without validation keep the last epoch
            if score < best_loss - cfg.min_delta or best_state is None:
                best_loss, best_epoch, waited = score, epoch, 0
                best_state = {k: v.detach().clone() for k, v in net.state_dict().items()}
            else:
                waited += 1
            if stopped == "time":
                break
            if len(val) and cfg.patience is not None and waited >= cfg.patience:
                stopped = "early"
                break
        net.load_state_dict(best_state)
    net.eval()
    return TrainedModel(model=net, spec=spec, preprocessing=prep, config=cfg, classes=names, target_mean=t_mean,
                        target_std=t_std, history=history, best_epoch=best_epoch, stopped=stopped,
                        train_seconds=time.perf_counter() - t0, n_train=len(fit), n_val=len(val),
                        val_rows=tuple(int(i) for i in val))

