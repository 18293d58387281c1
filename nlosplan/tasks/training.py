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
from dataclasses import asdict, dataclass, field
from typing import Callable

import numpy as np
import torch
from sklearn.model_selection import train_test_split
from torch import nn

from nlosplan.errors import UserError
from nlosplan.tasks.models import ModelSpec, model_from_spec

__all__ = ["CHECKPOINT_FORMAT", "Preprocessing", "TrainConfig", "TrainedModel", "apply_histogram_transform",
           "load_checkpoint", "save_checkpoint", "train_model"]

@dataclass(frozen=True)
class Preprocessing:
    """Histogram transform with its training-set statistics (DENALI's ``apply_histogram_transform``).

    Parameters
    ----------
    log_transform : bool
        Apply ``log1p(clip(x, 0))`` first (compresses the direct-peak counts).
    normalize : bool
        Then ``(x - mean) / std`` with scalars.
    mean, std : float
        Statistics of the (log-transformed) training histograms, over all entries.
    """

    log_transform: bool = True
    normalize: bool = True
    mean: float = 0.0
    std: float = 1.0

    @classmethod
    def fit(cls, histograms, *, log_transform: bool = True, normalize: bool = True) -> "Preprocessing":
        """Statistics from training histograms, shape (N, rows, cols, bins)."""
        x = np.asarray(histograms, dtype=np.float32)
        if log_transform:
            x = np.log1p(np.clip(x, 0.0, None))
        if not normalize:
            return cls(log_transform, False, 0.0, 1.0)
        return cls(log_transform, True, float(x.mean(dtype=np.float64)), float(x.std(dtype=np.float64) + 1e-6))

    def apply(self, histograms) -> np.ndarray:
        """Transformed histograms, float32, same shape."""
        x = np.asarray(histograms, dtype=np.float32)
        if self.log_transform:
            x = np.log1p(np.clip(x, 0.0, None))
        if self.normalize:
            x = (x - np.float32(self.mean)) / np.float32(self.std)
        return x.astype(np.float32, copy=False)


def apply_histogram_transform(histograms, *, log_transform: bool = True, normalize: bool = True,
                              stats: Preprocessing | None = None) -> tuple[np.ndarray, Preprocessing]:
    """DENALI's transform: fit the statistics on ``histograms`` unless ``stats`` is given, then apply.

    Returns
    -------
    ndarray of float32, same shape
    Preprocessing
    """
    stats = stats or Preprocessing.fit(histograms, log_transform=log_transform, normalize=normalize)
    return stats.apply(histograms), stats


@dataclass(frozen=True)
class TrainConfig:
    """Training settings.

    Parameters
    ----------
    lr : float
        Adam learning rate.
    batch_size : int
    max_epochs : int
    patience : int or None
        Epochs without a better validation loss before stopping; None trains
        ``max_epochs`` (the best validation epoch is still restored).
    val_fraction : float
        Part of the training rows used for validation (0: none; then the last
        epoch's weights are kept).
    max_seconds : float or None
        Wall-clock budget; training stops at the first batch past it.
    log_transform, normalize : bool
        Histogram preprocessing.
    standardize_targets : bool
        Regress standardized (x, y) (localization only).
    weight_decay : float
    min_delta : float
        Smallest decrease of the validation loss that counts as better.
    seed : int
    """

    lr: float = 1e-3
    batch_size: int = 64
    max_epochs: int = 60
    patience: int | None = 8
    val_fraction: float = 0.15
    max_seconds: float | None = None
    log_transform: bool = True
    normalize: bool = True
    standardize_targets: bool = True
    weight_decay: float = 0.0
    min_delta: float = 0.0
    seed: int = 42

    def __post_init__(self) -> None:
        if not (self.lr > 0 and math.isfinite(self.lr)):
            raise UserError(f"lr={self.lr} must be > 0")
        if self.batch_size < 1 or self.max_epochs < 1:
            raise UserError(f"batch_size={self.batch_size} and max_epochs={self.max_epochs} must be >= 1")
        if self.patience is not None and self.patience < 1:
            raise UserError(f"patience={self.patience} must be >= 1 (or None)")
        if not 0 <= self.val_fraction < 1:
            raise UserError(f"val_fraction={self.val_fraction} must be in [0, 1)")
        if self.max_seconds is not None and not self.max_seconds > 0:
            raise UserError(f"max_seconds={self.max_seconds} must be > 0 (or None)")


@dataclass(eq=False)
class TrainedModel:
    """A trained model with everything needed to use and reproduce it.

    Attributes
    ----------
    model : torch.nn.Module
        In eval mode, on the CPU.
    spec : ModelSpec
    preprocessing : Preprocessing
    config : TrainConfig
    classes : tuple of str or None
        Class names, index order of the outputs (classification).
    target_mean, target_std : tuple of float or None
        Standardization of (x, y), metres (localization).
    history : list of dict
        Per epoch: ``epoch``, ``train_loss``, ``val_loss`` (None without
        validation), ``seconds`` (since the start).
    best_epoch : int
        Epoch whose weights were kept.
    stopped : str
        ``"early"``, ``"max_epochs"`` or ``"time"``.
    train_seconds : float
        Wall-clock seconds of training (preprocessing included).
    n_train, n_val : int
        Rows used to fit and to validate.
    val_rows : tuple of int
        Indices (into the training histograms) of the validation rows.
    """

    model: nn.Module
    spec: ModelSpec
    preprocessing: Preprocessing
    config: TrainConfig
    classes: tuple[str, ...] | None = None
    target_mean: tuple[float, float] | None = None
    target_std: tuple[float, float] | None = None
    history: list[dict] = field(default_factory=list)
    best_epoch: int = 0
    stopped: str = "max_epochs"
    train_seconds: float = 0.0
    n_train: int = 0
    n_val: int = 0
    val_rows: tuple[int, ...] = ()

    def predict(self, histograms, *, batch_size: int = 1024) -> np.ndarray:
        """Model outputs for raw histograms.

        Parameters
        ----------
        histograms : array_like, shape (N, rows, cols, bins)
            Counts, as in the training data (the stored preprocessing is applied).

        Returns
        -------
        ndarray of float64
            (N, 2) predicted (x, y) in metres for ``"loc"``; (N, classes) logits otherwise.
        """
        x = torch.from_numpy(self.preprocessing.apply(histograms))
        self.model.eval()
        with torch.inference_mode():
            out = torch.cat([self.model(x[i:i + batch_size]) for i in range(0, len(x), batch_size)]) if len(x) else \
                torch.zeros((0, self.spec.n_outputs))
        out = out.numpy().astype(np.float64)
        if self.spec.task == "loc" and self.target_mean is not None:
            out = out * np.asarray(self.target_std) + np.asarray(self.target_mean)
        return out

    def predict_labels(self, histograms) -> np.ndarray:
        """Predicted class names, shape (N,) (classification models only)."""
        if self.classes is None:
            raise UserError("predict_labels needs a classification model")
        return np.asarray(self.classes, dtype=object)[self.predict(histograms).argmax(axis=1)]

    def meta(self) -> dict:
        """Everything but the weights, JSON-able."""
        from nlosplan import __version__

        return {"spec": self.spec.to_dict(), "preprocessing": asdict(self.preprocessing), "config": asdict(self.config),
                "classes": None if self.classes is None else list(self.classes),
                "target_mean": None if self.target_mean is None else list(self.target_mean),
                "target_std": None if self.target_std is None else list(self.target_std),
                "history": self.history, "best_epoch": self.best_epoch, "stopped": self.stopped,
                "train_seconds": self.train_seconds, "n_train": self.n_train, "n_val": self.n_val,
                "val_rows": list(self.val_rows), "versions": {"nlosplan": __version__, "torch": torch.__version__}}


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
    if task == "loc":
        y_np = np.asarray(targets, dtype=np.float64)
        if y_np.shape != (len(x_raw), 2):
            raise UserError(f"localization targets must be (N, 2), got {y_np.shape}")
        strat_labels, names = None, None
    else:
        raw_labels = np.asarray(targets).astype(str)
        if raw_labels.shape != (len(x_raw),):
            raise UserError(f"class targets must be (N,), got {raw_labels.shape}")
        names = tuple(sorted(set(raw_labels))) if classes is None else tuple(str(c) for c in classes)
        lookup = {c: i for i, c in enumerate(names)}
        unknown = sorted(set(raw_labels) - set(lookup))
        if unknown:
            raise UserError(f"training labels {', '.join(unknown[:5])} are not among the classes")
        if len(names) < 2:
            raise UserError(f"classification needs at least 2 classes, got {len(names)}")
        y_np = np.array([lookup[c] for c in raw_labels], dtype=np.int64)
        strat_labels = y_np
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


# Checkpoints live in their own module; re-exported here (that module imports this one only inside its functions).
from nlosplan.tasks.checkpoints import CHECKPOINT_FORMAT, load_checkpoint, save_checkpoint  # noqa: E402
