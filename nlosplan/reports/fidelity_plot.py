"""Error against run time of both simulators (``nlosplan bench fidelity --plot``)."""

from __future__ import annotations

from pathlib import Path

from nlosplan.reports.figures import save_figure


def plot_fidelity(rows: list[dict], path, *, reference_self_error: float | None = None, title: str = "") -> Path:
    """Log-log relative L1 error (%) against seconds per scene, one line per backend.

    Parameters
    ----------
    rows : list of dict
        ``backend``, ``fidelity``, ``seconds``, ``rel_l1_error``.
    path : str or Path
        PNG to write.
    reference_self_error : float, optional
        The reference's own error (relative): a shaded band below it.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.8, 4.6))
    for backend, color, marker in (("fast", "C0", "o"), ("mitsuba", "C1", "s")):
        rs = [r for r in rows if r["backend"] == backend]
        if not rs:
            continue
        xs = [r["seconds"] for r in rs]
        ys = [100 * max(r["rel_l1_error"], 1e-6) for r in rs]
        ax.plot(xs, ys, marker=marker, color=color, label=f"{backend} backend")
        for r, x, y in zip(rs, xs, ys):
            ax.annotate(r["fidelity"], (x, y), textcoords="offset points", xytext=(5, 5), fontsize=8, color=color)
    if reference_self_error:
        ax.axhspan(1e-4, 100 * reference_self_error, color="0.5", alpha=0.15, lw=0, label="reference's own error")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds per scene")
    ax.set_ylabel("relative L1 error of the three-bounce histogram (%)")
    ax.grid(True, which="both", lw=0.3, alpha=0.5)
    ax.legend(fontsize=8)
    ys_all = [100 * max(r["rel_l1_error"], 1e-6) for r in rows]
    ax.set_ylim(min(ys_all + [100 * (reference_self_error or 1)]) / 2, max(ys_all) * 2)
    if title:
        ax.set_title(title, fontsize=10)
    return save_figure(fig, path, dpi=110, tight=True)
