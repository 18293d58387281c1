"""The types of training: preprocessing, settings, and a trained model with everything to use and reproduce it.

Kept apart from :mod:`nlosplan.tasks.training` (which trains) so that
:mod:`nlosplan.tasks.checkpoints` can rebuild a :class:`TrainedModel`
without importing the training loop, and the training loop can write
checkpoints: neither imports the other.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from torch import nn

from nlosplan.errors import UserError
from nlosplan.tasks.models import ModelSpec

__all__ = ["Preprocessing", "TrainConfig", "TrainedModel", "apply_histogram_transform"]


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
