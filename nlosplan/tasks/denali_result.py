"""The result of one cell of DENALI's recipe (:func:`nlosplan.tasks.denali_recipe.train_denali_cell`).

Kept apart from the training loop so that a caller can hold and read results without importing it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

__all__ = ["CellResult"]


@dataclass(frozen=True, eq=False)
class CellResult:
    """One trained cell of DENALI's recipe.

    Attributes
    ----------
    task, model : str
    metric : {"loc_rmse", "top1_acc"}
        What is reported (loc_rmse in metres).
    selection : {"mae", "top1_acc"}
        DENALI's criterion for its epoch (lower MAE, higher top-1).
    mode : {"denali", "validation"}
        ``"denali"``: trained on DENALI's whole training split; ``"validation"``: on it minus a seeded tenth.
    predicted : float
        ``metric`` at the best-on-test epoch (DENALI's choice; ``best_epoch``).
    predicted_last_epoch : float
        ``metric`` at the last epoch.
    predicted_validation_epoch : float or None
        ``metric`` on the test set at the epoch chosen on the held-out tenth (``validation_epoch``);
        None in ``"denali"`` mode.
    history : tuple of dict
        Per epoch: ``epoch``, ``train_loss`` (mean over batches of the loss DENALI minimises), ``test``
        (``loc_rmse``/``mae``/``mse`` or ``top1_acc``/``top5_acc``/``macro_f1``), ``val`` (or None),
        ``seconds`` since the start.
    n_train, n_val, n_test : int
    test_index : ndarray of int
        The test rows, in scoring order.
    predictions : dict of str to ndarray
        Test predictions (class indices, or (N, 2) x, y in metres) at ``"best"``, ``"last"`` and (validation
        mode) ``"validation"`` epochs.
    classes : tuple of str or None
        Class names in output order (sorted, as DENALI's LabelEncoder).
    settings : dict
        DENALI's ``lr``, ``epochs`` (of the cell), ``batch_size``, ``log_zscore`` and the ``epochs`` run.
    preprocessing : dict
    seconds : float
    device : str
    seed : int
    torch_threads : int
    """

    task: str
    model: str
    metric: str
    selection: str
    mode: str
    predicted: float
    best_epoch: int
    predicted_last_epoch: float
    epochs: int
    predicted_validation_epoch: float | None
    validation_epoch: int | None
    history: tuple
    n_train: int
    n_val: int
    n_test: int
    test_index: np.ndarray
    predictions: dict
    classes: tuple | None
    settings: dict
    preprocessing: dict
    seconds: float
    device: str
    seed: int
    torch_threads: int = field(default=1)

    def to_dict(self, history: bool = True) -> dict:
        """Plain JSON-able dict (no predictions or indices; ``history`` optional)."""
        out = {k: getattr(self, k) for k in (
            "task", "model", "metric", "selection", "mode", "predicted", "best_epoch", "predicted_last_epoch",
            "epochs", "predicted_validation_epoch", "validation_epoch", "n_train", "n_val", "n_test", "settings",
            "preprocessing", "seconds", "device", "seed", "torch_threads")}
        if history:
            out["history"] = list(self.history)
        return out
