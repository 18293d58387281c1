"""Per-zone histogram figure."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nlosplan.reports.figures import pyplot, save_figure


def plot_zone_histograms(
    histogram: np.ndarray,
    path: str | Path,
    *,
    bin_width_ps: float,
    start_offset_ps: float = 0.0,
    title: str = "",
    samples: np.ndarray | None = None,
    log: bool = True,
) -> Path:
    """Write a PNG with one panel per zone.

    Parameters
    ----------
    histogram : ndarray, shape (rows, cols, n_bins)
        Expected counts per zone.
    path : str or Path
        Output PNG path.
    bin_width_ps, start_offset_ps : float
        Time axis: bin ``j`` starts at ``start_offset_ps + j * bin_width_ps``.
    title : str
        Figure title.
    samples : ndarray, shape (rows, cols, n_bins), optional
        One noisy capture drawn over the expectation.
    log : bool
        Logarithmic count axis (the direct peak and the floor differ by decades).

    Returns
    -------
    Path
        The written file.
    """
    plt = pyplot()

    h = np.asarray(histogram, dtype=float)
    rows, cols, n = h.shape
    t_ns = (start_offset_ps + bin_width_ps * (np.arange(n) + 0.5)) * 1e-3
    size = min(2.2 * cols + 1.0, 16.0), min(1.7 * rows + 1.0, 14.0)
    fig, axes = plt.subplots(rows, cols, figsize=size, sharex=True, sharey=True, squeeze=False)
    floor = max(h[h > 0].min() * 0.5, 1e-3) if np.any(h > 0) else 1e-3
    for r in range(rows):
        for c in range(cols):
            ax = axes[r, c]
            if samples is not None:
                ax.step(t_ns, np.maximum(samples[r, c], floor), where="mid", color="0.6", lw=0.6, label="one capture")
            ax.step(t_ns, np.maximum(h[r, c], floor), where="mid", color="C0", lw=1.0, label="expected")
            if log:
                ax.set_yscale("log")
            if rows * cols <= 16:
                ax.set_title(f"zone ({r},{c})", fontsize=8)
            ax.tick_params(labelsize=6)
    for ax in axes[-1]:
        ax.set_xlabel("time (ns)", fontsize=7)
    for ax in axes[:, 0]:
        ax.set_ylabel("counts", fontsize=7)
    axes[0, 0].legend(fontsize=6, loc="upper right")
    if title:
        fig.suptitle(title, fontsize=9)
    return save_figure(fig, path, dpi=110, tight=True)
