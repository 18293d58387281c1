"""Per-zone residuals of plane captures against distance, before and after a model change (PNG)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

#: What each panel row shows: key of the per-capture scores, axis label, target band.
METRICS = {"subbin_err": ("sub-bin peak error (bins)", (-0.15, 0.15)),
           "l1": ("normalized L1 of the shape", (0.0, 0.15)),
           "amp_ratio": ("amplitude pred/meas", (0.8, 1.25))}


def plot_plane_residuals(runs: dict, path, *, metric: str = "subbin_err", rows: int = 3, cols: int = 3,
                         title: str = "") -> Path:
    """One panel per zone: ``metric`` of every capture against distance, one line per run.

    Parameters
    ----------
    runs : dict
        ``label -> per_capture`` (``distance_m`` (N,) and ``metric`` (N, Z) lists, as the score-only
        mode and the cross-validation return them).
    path : str or Path
        PNG to write (atomically).
    metric : {"subbin_err", "l1", "amp_ratio"}
    rows, cols : int
        Zone grid (row-major zones).

    Returns
    -------
    Path
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    label, band = METRICS[metric]
    fig, axes = plt.subplots(rows, cols, figsize=(3.4 * cols, 2.6 * rows), sharex=True, sharey=True, squeeze=False)
    for z in range(rows * cols):
        ax = axes[z // cols, z % cols]
        ax.axhspan(*band, color="0.92", zorder=0)
        for name, per in runs.items():
            d = np.asarray(per["distance_m"], dtype=np.float64)
            v = np.asarray(per[metric], dtype=np.float64)[:, z]
            ax.plot(100 * d, v, ".-", ms=3, lw=0.8, label=name)
        ax.set_title(f"zone {z}", fontsize=9)
        if metric == "amp_ratio":
            ax.set_yscale("log")
        if z // cols == rows - 1:
            ax.set_xlabel("distance (cm)")
        if z % cols == 0:
            ax.set_ylabel(label, fontsize=8)
    axes[0, 0].legend(fontsize=7)
    fig.suptitle(title or f"{label}: grey band = target", fontsize=10)
    fig.tight_layout()
    from nlosplan.reports.figures import save_figure

    return save_figure(fig, path, dpi=110)
