"""Shared matplotlib plumbing of the report figures (headless backend, saving)."""

from __future__ import annotations

from pathlib import Path

from nlosplan.files import atomic_path


def pyplot():
    """``matplotlib.pyplot`` on the headless Agg backend (imported only when a figure is drawn)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig, path: str | Path, *, dpi: int = 110, tight: bool = False) -> Path:
    """Write ``fig`` at ``path`` atomically (folders created; the suffix picks the format, e.g. PNG), close it,
    and return the path."""
    plt = pyplot()
    try:
        if tight:
            fig.tight_layout()
        path = Path(path)
        with atomic_path(path) as tmp:
            fig.savefig(tmp, dpi=dpi, format=path.suffix.lstrip(".").lower() or "png")
    finally:
        plt.close(fig)
    return path
