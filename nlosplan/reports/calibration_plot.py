"""Residual plot of a calibration: measured and fitted histograms, and their Poisson residuals."""

from __future__ import annotations

from pathlib import Path

from nlosplan.reports.figures import save_figure

import numpy as np


def plot_calibration(measured, predicted, labels, path, *, title: str = "", n_show: int = 6) -> Path:
    """Measured vs fitted counts (log scale) and Pearson residuals for a few captures.

    Parameters
    ----------
    measured, predicted : ndarray, shape (N, B)
        Counts of N capture zones and their fitted expectation.
    labels : sequence of str, length N
    path : str or Path
        PNG to write.
    n_show : int
        Captures shown, spread over the N given.

    Returns
    -------
    Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    measured = np.asarray(measured, dtype=np.float64)
    predicted = np.asarray(predicted, dtype=np.float64)
    pick = np.unique(np.linspace(0, measured.shape[0] - 1, min(n_show, measured.shape[0])).round().astype(int))
    fig, axes = plt.subplots(2, len(pick), figsize=(3.2 * len(pick), 5.5), sharex=True, squeeze=False,
                             gridspec_kw={"height_ratios": [2, 1]})
    bins = np.arange(measured.shape[-1])
    for col, i in enumerate(pick):
        ax, rx = axes[0, col], axes[1, col]
        ax.semilogy(bins, np.maximum(measured[i], 0.5), color="0.3", lw=1, label="measured")
        ax.semilogy(bins, np.maximum(predicted[i], 0.5), color="tab:red", lw=1, ls="--", label="fitted")
        ax.set_title(str(labels[i]), fontsize=9)
        resid = (measured[i] - predicted[i]) / np.sqrt(np.maximum(predicted[i], 1.0))
        rx.plot(bins, resid, color="tab:blue", lw=0.8)
        rx.axhline(0, color="0.5", lw=0.5)
        rx.set_xlabel("bin")
        if col == 0:
            ax.set_ylabel("counts")
            rx.set_ylabel("(meas - fit) / sqrt(fit)")
            ax.legend(fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    return save_figure(fig, path, dpi=110, tight=True)
