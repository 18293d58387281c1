"""A proposed capture batch as a table and a plot of gantry positions (the approval gate's view)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nlosplan.reports.figures import pyplot, save_figure
from nlosplan.reports.tables import format_table

__all__ = ["batch_table", "plot_batch"]


def batch_table(batch: list[dict]) -> str:
    """Visiting order, id, gantry position (mm) and label (m) of each proposed capture."""
    rows = [{"#": k + 1, "id": p["id"], "x_mm": round(p["x_mm"], 1), "y_mm": round(p["y_mm"], 1),
             "label_x_m": round(p["label_xy"][0], 4), "label_y_m": round(p["label_xy"][1], 4)}
            for k, p in enumerate(batch)]
    return format_table(rows)


def plot_batch(batch: list[dict], candidates_mm, captured_mm, start_mm, path, *, title: str = "") -> Path:
    """Candidates (grey), positions captured (blue), the proposed route from the gantry (red, numbered)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.2, 5.2))
    c = np.asarray(candidates_mm, dtype=float).reshape(-1, 2)
    ax.scatter(c[:, 0], c[:, 1], s=8, color="0.75", label="candidates")
    done = np.asarray(captured_mm, dtype=float).reshape(-1, 2)
    if len(done):
        ax.scatter(done[:, 0], done[:, 1], s=25, color="C0", label="captured")
    route = np.vstack([np.asarray(start_mm, float).reshape(1, 2), [[p["x_mm"], p["y_mm"]] for p in batch]])
    ax.plot(route[:, 0], route[:, 1], "-", color="C3", lw=1.2)
    ax.scatter(route[1:, 0], route[1:, 1], s=45, color="C3", label="proposed", zorder=3)
    ax.scatter(route[:1, 0], route[:1, 1], s=60, marker="s", color="k", label="gantry now", zorder=3)
    for k, (x, y) in enumerate(route[1:]):
        ax.annotate(str(k + 1), (x, y), textcoords="offset points", xytext=(4, 4), fontsize=8)
    ax.set(xlabel="gantry x (mm)", ylabel="gantry y (mm)", title=title or f"proposed batch of {len(batch)}",
           aspect="equal")
    ax.legend(fontsize=7, loc="upper right")
    return save_figure(fig, path, tight=True)
