"""Error against run time figure (``nlosplan bench simulate``)."""

from __future__ import annotations

import math
from pathlib import Path

from nlosplan.reports.figures import pyplot, save_figure

#: Errors below this (relative) are drawn at it on the log axis.
ERROR_FLOOR = 1e-6


def plot_error_runtime(
    levels: list[dict],
    path: str | Path,
    *,
    title: str = "",
    target_rel_l1: float = 0.01,
    target_scenes_per_second: float = 200.0,
    stretch_scenes_per_second: float | None = 1000.0,
    reference_self_error: float | None = None,
) -> Path:
    """Write a log-log PNG of relative L1 error (%) against seconds per scene.

    Parameters
    ----------
    levels : list of dict
        Rows of ``bench_simulate(...)["levels"]``: ``fidelity``,
        ``rel_l1_error``, ``seconds_per_scene_batched``, ``seconds_single``.
    path : str or Path
        Output PNG path (parent folders are created).
    title : str
        Figure title.
    target_rel_l1 : float
        Error target (relative), drawn as a horizontal line.
    target_scenes_per_second : float
        Throughput target, drawn as a vertical line at ``1 / target`` s.
    stretch_scenes_per_second : float, optional
        Stretch throughput, a dotted vertical line.
    reference_self_error : float, optional
        The reference's own error (relative), a shaded band below it: errors
        there are not resolved.

    Returns
    -------
    Path
        The written file.
    """
    plt = pyplot()

    fig, ax = plt.subplots(figsize=(7.2, 5.0))
    pts_err, pts_t = [], []
    for mode, key, marker, color, face, offset in (
        ("batched (all positions per call)", "seconds_per_scene_batched", "o", "C0", "C0", (-8, 7)),
        ("one scene per call", "seconds_single", "s", "C1", "none", (7, -12)),
    ):
        xs = [float(r[key]) for r in levels]
        ys = [100 * max(float(r["rel_l1_error"]), ERROR_FLOOR) for r in levels]
        ax.plot(xs, ys, marker=marker, color=color, mfc=face, mew=1.5, ms=8, lw=1.0, alpha=0.9, label=mode)
        pts_t += xs
        pts_err += ys
        for i, (r, x, y) in enumerate(zip(levels, xs, ys)):
            dx, dy = offset if i % 2 == 0 else (offset[0], -offset[1] - 4)  # alternate sides: neighbours stay apart
            ax.annotate(r["fidelity"], (x, y), textcoords="offset points", xytext=(dx, dy), fontsize=8, color=color,
                        ha="right" if dx < 0 else "left")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.axhline(100 * target_rel_l1, color="C3", ls="--", lw=1.0)
    ax.axvline(1.0 / target_scenes_per_second, color="C2", ls="--", lw=1.0)
    xs_lines = [1.0 / target_scenes_per_second]
    if stretch_scenes_per_second:
        ax.axvline(1.0 / stretch_scenes_per_second, color="C2", ls=":", lw=1.0)
        xs_lines.append(1.0 / stretch_scenes_per_second)
    finite_t = [t for t in pts_t if math.isfinite(t) and t > 0] + xs_lines
    finite_e = [e for e in pts_err if math.isfinite(e) and e > 0] + [100 * target_rel_l1]
    if reference_self_error is not None and reference_self_error > 0:
        finite_e.append(100 * reference_self_error)
    x_lo, x_hi = min(finite_t) / 2.5, max(finite_t) * 2.5
    y_lo, y_hi = min(finite_e) / 3.0, max(finite_e) * 3.0
    ax.set_xlim(x_lo, x_hi)
    ax.set_ylim(y_lo, y_hi)
    ax.text(x_hi / 1.15, 100 * target_rel_l1 * 1.08, f"{100 * target_rel_l1:g} % target", color="C3", fontsize=8,
            ha="right", va="bottom")
    ax.text(1.0 / target_scenes_per_second * 1.06, y_hi / 1.15, f"{target_scenes_per_second:g}/s", color="C2",
            fontsize=8, ha="left", va="top")
    if stretch_scenes_per_second:
        ax.text(1.0 / stretch_scenes_per_second * 1.06, y_hi / 1.15, f"{stretch_scenes_per_second:g}/s", color="C2",
                fontsize=8, ha="left", va="top")
    ax.fill_between([x_lo, 1.0 / target_scenes_per_second], y_lo, 100 * target_rel_l1, color="C2", alpha=0.07, lw=0)
    ax.text(x_lo * 1.15, 100 * target_rel_l1 / 1.15, "meets the target", color="C2", fontsize=8, va="top")
    if reference_self_error is not None and reference_self_error > 0:
        ax.axhspan(y_lo, 100 * reference_self_error, color="0.5", alpha=0.15, lw=0)
        ax.text(x_lo * 1.15, 100 * reference_self_error / 1.1, "reference's own error", color="0.35", fontsize=8,
                va="top")
    ax.set_xlabel("seconds per scene (expected histograms, compile excluded)")
    ax.set_ylabel("relative L1 error of the three-bounce histogram (%)")
    ax.grid(True, which="major", lw=0.4, alpha=0.5)
    ax.grid(True, which="minor", lw=0.2, alpha=0.3)
    ax.legend(fontsize=8, loc="upper right")
    if title:
        ax.set_title(title, fontsize=10)
    return save_figure(fig, path, dpi=120, tight=True)
