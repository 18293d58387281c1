"""Per-zone figure of a simulated NLOS capture: total, direct, object and signal."""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from nlosplan.reports.figures import pyplot, save_figure

# colour-blind-safe (Okabe-Ito) colours, one per curve
_COLORS = {
    "capture": "0.72",
    "expected": "#000000",
    "direct": "#0072B2",
    "object": "#009E73",
    "signal": "#D55E00",
}
_MAX_SUBSET_COLS = 4
_FEW_PANELS = 16


@dataclass(frozen=True)
class _Layout:
    """Fixed figure geometry in inches: panels, gaps between them, margins.

    A grid of panels with labels on its outer edges only needs no layout
    engine; fixed margins keep the figure quick to draw (64 panels with twin
    axes) and the same for every capture.
    """

    rows: int
    cols: int
    small: bool
    panel: tuple[float, float]
    gap: tuple[float, float]
    margins: tuple[float, float, float, float]  # left, right, top, bottom
    legend_cols: int

    @property
    def size(self) -> tuple[float, float]:
        left, right, top, bottom = self.margins
        return (left + right + self.cols * self.panel[0] + (self.cols - 1) * self.gap[0],
                top + bottom + self.rows * self.panel[1] + (self.rows - 1) * self.gap[1])

    def apply(self, fig) -> None:
        """Place the subplots of ``fig``."""
        (w, h), (left, right, top, bottom) = self.size, self.margins
        fig.subplots_adjust(left=left / w, right=1 - right / w, top=1 - top / h, bottom=bottom / h,
                            wspace=self.gap[0] / self.panel[0], hspace=self.gap[1] / self.panel[1])


def _layout(rows: int, cols: int, n_panels: int, n_handles: int, title_lines: int) -> _Layout:
    small = rows * cols > _FEW_PANELS
    legend_cols = n_handles if cols >= 3 else 3
    legend_rows = math.ceil(n_handles / legend_cols)
    if small:
        panel, gap = (1.85, 1.3), (0.1, 0.1)
    else:
        partial = n_panels < rows * cols  # the row above an empty slot shows its time axis
        panel, gap = (max(2.5, 7.0 / cols), 1.75), (0.12, 0.32 + (0.45 if partial else 0.0))
    top = 0.3 + 0.2 * title_lines
    bottom = 0.5 + 0.22 * legend_rows + 0.1
    return _Layout(rows, cols, small, panel, gap, (0.75, 0.7, top, bottom), legend_cols)


def _panels(expected: np.ndarray, zone_labels: Sequence[str] | None) -> tuple[int, int, list[str]]:
    """Panel grid (rows, cols) and one label per zone for a grid or a zone subset."""
    if expected.ndim == 3:
        rows, cols = expected.shape[:2]
        labels = [f"zone ({r},{c})" for r in range(rows) for c in range(cols)]
    else:
        k = expected.shape[0]
        cols = min(k, _MAX_SUBSET_COLS)
        rows = math.ceil(k / cols)
        labels = [f"zone {i}" for i in range(k)]
    if zone_labels is not None:
        if len(zone_labels) != len(labels):
            raise ValueError(f"zone_labels has {len(zone_labels)} labels for {len(labels)} zones")
        labels = list(zone_labels)
    return rows, cols, labels


def _flat(a: np.ndarray | None, n_bins: int) -> np.ndarray | None:
    return None if a is None else np.asarray(a, dtype=float).reshape(-1, n_bins)


def _log_floor(expected: np.ndarray, obj: np.ndarray) -> float:
    """Bottom of the log axis, a power of ten.

    A decade below the smallest positive expected count, and at least two
    decades below the object part's peak, so a weak object return under a
    high ambient floor stays visible.
    """
    candidates = [float(expected[expected > 0].min()) / 10] if np.any(expected > 0) else []
    if np.max(obj, initial=0.0) > 0:
        candidates.append(float(np.max(obj)) / 100)
    if not candidates:
        return 1e-3
    return 10.0 ** math.floor(math.log10(min(candidates)))


def _above(y: np.ndarray, floor: float) -> np.ndarray:
    """``y`` with values at or below ``floor`` hidden (NaN), so a log line stops instead of hugging the axis."""
    return np.where(y > floor, y, np.nan)


def _draw_panel(ax, t_ns, i, curves, limits, small):
    """One zone: log counts on ``ax``, the signal on a twin linear axis (returned)."""
    floor = limits["floor"]
    if curves["capture"] is not None:
        ax.step(t_ns, _above(curves["capture"][i], floor), where="mid", color=_COLORS["capture"], lw=0.7,
                label="one noisy capture")
    ax.plot(t_ns, _above(curves["expected"][i], floor), color=_COLORS["expected"], lw=1.3, label="expected total")
    ax.plot(t_ns, _above(curves["direct"][i], floor), color=_COLORS["direct"], lw=1.0, ls="--",
            label="direct (first bounce)")
    ax.plot(t_ns, _above(curves["object"][i], floor), color=_COLORS["object"], lw=1.2,
            label="object (three bounces)")
    ax.set_yscale("log")
    ax.set_ylim(floor, limits["log_top"])
    twin = ax.twinx()
    sig = curves["signal"][i]
    twin.fill_between(t_ns, 0, np.maximum(sig, 0), step="mid", color=_COLORS["signal"], alpha=0.25, lw=0)
    twin.step(t_ns, sig, where="mid", color=_COLORS["signal"], lw=0.9, label="signal: total - no object (right axis)")
    twin.set_ylim(0, limits["signal_top"])
    size = 6 if small else 7
    ax.tick_params(labelsize=size, length=2 if small else 3)
    twin.tick_params(labelsize=size, length=2 if small else 3, colors=_COLORS["signal"])
    return twin


def plot_simulation(
    expected: np.ndarray,
    parts: Mapping[str, np.ndarray],
    signal: np.ndarray,
    path: str | Path,
    *,
    bin_width_ps: float,
    start_offset_ps: float = 0.0,
    title: str = "",
    samples: np.ndarray | None = None,
    zone_labels: Sequence[str] | None = None,
) -> Path:
    """Write a PNG with one panel per zone of a simulated NLOS capture.

    Each panel shows, on a logarithmic count axis, the expected total, its
    direct (first-bounce) part and the hidden object's three-bounce part,
    with one noisy capture in light grey behind them; and, on a linear axis
    at the right shared by all panels, the background-subtracted signal
    (expected total minus the no-object capture), filled.

    Parameters
    ----------
    expected : ndarray, shape (rows, cols, n_bins) or (n_zones, n_bins)
        Expected counts with the object: a full zone grid, or a subset of
        zones drawn as a row (wrapping after four panels).
    parts : mapping of str to ndarray, same shape as ``expected``
        ``"direct"`` and ``"object"`` parts of the expectation.
    signal : ndarray, same shape as ``expected``
        Expected counts minus the no-object expectation.
    path : str or Path
        Output PNG path (parent folders are created).
    bin_width_ps, start_offset_ps : float
        Time axis: bin ``j`` covers ``start_offset_ps + j * bin_width_ps`` to
        the next bin, drawn at its centre in ns.
    title : str
        Figure title (scene, object, sensor, ...).
    samples : ndarray, same shape as ``expected``, optional
        One noisy capture.
    zone_labels : sequence of str, optional
        One label per zone (default ``zone (r,c)`` for a grid, ``zone i`` for
        a subset); panel labels are drawn for up to 16 panels.

    Returns
    -------
    Path
        The written file.

    Raises
    ------
    ValueError
        Arrays of different shapes, or a missing part.
    """
    plt = pyplot()

    exp = np.asarray(expected, dtype=float)
    if exp.ndim not in (2, 3):
        raise ValueError(f"expected must be (rows, cols, bins) or (zones, bins), not shape {exp.shape}")
    n_bins = exp.shape[-1]
    for name, arr in (("direct", parts.get("direct")), ("object", parts.get("object")), ("signal", signal),
                      ("samples", samples)):
        if arr is None and name != "samples":
            raise ValueError(f"parts[{name!r}] is missing")
        if arr is not None and np.shape(arr) != exp.shape:
            raise ValueError(f"{name} has shape {np.shape(arr)}, expected {exp.shape}")
    rows, cols, labels = _panels(exp, zone_labels)
    curves = {"expected": _flat(exp, n_bins), "direct": _flat(parts["direct"], n_bins),
              "object": _flat(parts["object"], n_bins), "signal": _flat(signal, n_bins),
              "capture": _flat(samples, n_bins)}
    limits = {"floor": _log_floor(exp, curves["object"]), "log_top": max(float(exp.max()), 1e-3) * 3.0,
              "signal_top": max(float(np.max(curves["signal"])) * 1.15, 1e-9)}
    t_ns = (start_offset_ps + bin_width_ps * (np.arange(n_bins) + 0.5)) * 1e-3
    lay = _layout(rows, cols, len(labels), 4 + (samples is not None), len(title.splitlines()) if title else 0)
    fig, axes = plt.subplots(rows, cols, figsize=lay.size, sharex=True, sharey=True, squeeze=False)
    lay.apply(fig)
    twins = {}
    for i in range(len(labels)):
        r, c = divmod(i, cols)
        twins[r, c] = _draw_panel(axes[r, c], t_ns, i, curves, limits, lay.small)
        if not lay.small:
            axes[r, c].set_title(labels[i], fontsize=8, pad=3)
    for i in range(len(labels), rows * cols):
        axes[divmod(i, cols)].set_axis_off()
    _label_edges(axes, twins, rows, cols, lay.small)
    handles = [h for ax in (axes[0, 0], twins[0, 0]) for h in ax.get_legend_handles_labels()[0]]
    fig.legend(handles=handles, loc="lower center", ncol=lay.legend_cols, fontsize=7 if lay.small else 8,
               frameon=False, borderaxespad=0.3)
    if title:
        fig.suptitle(title, fontsize=10, y=1 - 0.08 / lay.size[1], va="top")
    return save_figure(fig, path, dpi=110)


def _label_edges(axes, twins, rows, cols, small) -> None:
    """Axis labels on the outer panels only; inner twin tick labels hidden."""
    fs = 6 if small else 8
    for (r, c), twin in twins.items():
        if c != cols - 1:
            twin.tick_params(labelright=False, length=0)
        elif r == rows // 2 or not small:
            twin.set_ylabel("signal (counts)", fontsize=fs, color=_COLORS["signal"])
    for c in range(cols):
        bottom = max(r for r in range(rows) if (r, c) in twins)
        axes[bottom, c].set_xlabel("time (ns)", fontsize=fs)
        axes[bottom, c].tick_params(labelbottom=True)
    for r in range(rows):
        if not small or r == rows // 2:
            axes[r, 0].set_ylabel("counts (log)", fontsize=fs)
