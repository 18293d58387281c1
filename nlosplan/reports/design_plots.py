"""Figures of the design report: trade-off curves, Pareto fronts, evaluators' error against run time, learning curves.

Every function takes the summary dict of
:func:`nlosplan.planner.design.summary.summarize` and a path, draws, saves a
PNG and returns its path. Nothing is computed here beyond plotting.
"""

from __future__ import annotations

import math
from pathlib import Path

from nlosplan.reports.figures import pyplot, save_figure

__all__ = ["plot_tradeoffs", "plot_pareto", "plot_evaluators", "plot_learning_curves"]

_LOG_X = ("photon_fraction", "bin_factor", "zones")
_AXIS_LABEL = {"zones": "zones (count)", "bin_factor": "bin width (ps)", "n_bins": "bins",
               "jitter_fwhm_ps": "jitter FWHM (ps)", "pulse_fwhm_ps": "pulse FWHM (ps)",
               "photon_fraction": "photon budget (x reference)"}


def _ylabel(req: str) -> str:
    return "localization RMSE (m)" if req.startswith("loc") else f"{req.split()[0]} top-1 accuracy"


def _threshold(req: str) -> float:
    return float(req.split()[3])


def plot_tradeoffs(summary: dict, requirement: str, path) -> Path:
    """Metric against each design parameter for one requirement; one line per zone layout where scanned.

    Solid: trained model (interval as error bars); dashed: the bound (CRLB or
    ideal observer); crosses: screened out by the bound; pluses: not met by implication (a costlier design of
    the line is not met, on an axis the metric is monotone in); grey line: the requirement.
    """
    plt = pyplot()
    curves = [c for c in summary["curves"] if c["requirement"] == requirement]
    axes = list(dict.fromkeys(c["axis"] for c in curves))
    n = max(len(axes), 1)
    cols = min(3, n)
    rows = math.ceil(n / cols)
    fig, axs = plt.subplots(rows, cols, figsize=(4.4 * cols, 3.4 * rows), squeeze=False)
    layouts = sorted({c["zones"] for c in curves}, key=lambda z: math.prod(int(v) for v in z.split("x")))
    colors = {z: plt.cm.viridis(i / max(len(layouts) - 1, 1)) for i, z in enumerate(layouts)}
    thr = _threshold(requirement)
    for ax, axis in zip(axs.flat, axes):
        for c in (c for c in curves if c["axis"] == axis):
            pts = c["points"]
            xs = [p["x"] for p in pts]
            col = colors[c["zones"]]
            tr = [(p["x"], p["value"], p["lo"], p["hi"]) for p in pts if p["value"] is not None]
            label = c["zones"] if axis != "zones" else "trained"
            if tr:
                x, v, lo, hi = zip(*tr)
                ax.errorbar(x, v, yerr=[[max(a - b, 0) for a, b in zip(v, lo)], [max(b - a, 0) for a, b in zip(v, hi)]],
                            color=col, marker="o", ms=3.5, lw=1.4, capsize=2, label=label)
            bd = [(p["x"], p["bound"]) for p in pts if p["bound"] is not None and math.isfinite(p["bound"])]
            if bd:
                ax.plot(*zip(*bd), color=col, ls="--", lw=1.0, alpha=0.8)
            imp = [p["x"] for p in pts if p.get("implied")]
            if imp:
                ax.plot(imp, [thr] * len(imp), "+", color=col, ms=7)
            scr = [p["x"] for p in pts if p["screened"]]
            if scr:
                y0 = [thr] * len(scr)
                ax.plot(scr, y0, "x", color=col, ms=7)
            if xs and axis in _LOG_X and min(xs) > 0:
                ax.set_xscale("log")
        ax.axhline(thr, color="0.4", lw=1, ls=":")
        ax.set_xlabel(_AXIS_LABEL.get(axis, axis))
        ax.set_ylabel(_ylabel(requirement))
        if requirement.startswith("loc"):
            ax.set_yscale("log")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7, title="zones" if axis != "zones" else None, title_fontsize=7)
    for ax in list(axs.flat)[len(axes):]:
        ax.axis("off")
    fig.suptitle(f"{requirement}: trained model (solid, 95 % interval), bound (dashed), "
                 "screened out (x), implied not met (+), requirement (dotted)", fontsize=9)
    return save_figure(fig, path, tight=True)


def plot_pareto(summary: dict, path) -> Path:
    """Cost against each task metric: every design trained (dots) and the Pareto front (line)."""
    plt = pyplot()
    reqs = list(summary["pareto"])
    fig, axs = plt.subplots(1, max(len(reqs), 1), figsize=(4.4 * max(len(reqs), 1), 3.4), squeeze=False)
    for ax, req in zip(axs.flat, reqs):
        front = summary["pareto"][req]
        ax.plot([p["cost"] for p in front], [p["value"] for p in front], "-o", color="C3", ms=4, label="Pareto front")
        cheap = next((c for c in summary["cheapest"] if c["requirement"] == req and c["design"]), None)
        if cheap:
            ax.plot([cheap["cost"]], [cheap["value"]], "*", color="k", ms=12, label="cheapest meeting it")
        ax.axhline(_threshold(req), color="0.4", lw=1, ls=":", label="requirement")
        ax.set_xlabel("relative cost (0 = cheapest in the space)")
        ax.set_ylabel(_ylabel(req))
        if req.startswith("loc"):
            ax.set_yscale("log")
        ax.set_title(req, fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return save_figure(fig, path, tight=True)


def plot_evaluators(summary: dict, path) -> Path:
    """Each evaluator's median run time against its median interval half-width (its error)."""
    plt = pyplot()
    fig, ax = plt.subplots(figsize=(5.6, 3.8))
    markers = {"loc": "o", "shape": "s", "size": "^"}
    for row in summary["evaluators"]:
        if not (math.isfinite(row["median_seconds"]) and math.isfinite(row["median_half_interval"])):
            continue
        err = row["median_half_interval"]
        ax.plot(row["median_seconds"], max(err, 1e-4), markers.get(row["task"], "o"),
                color="C0" if row["evaluator"] == "bound" else "C1", ms=8,
                label=f"{row['evaluator']} {row['task']} ({row['evaluations']})")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("median seconds per evaluation")
    ax.set_ylabel("median 95 % half-interval (m or accuracy)")
    ax.set_title("evaluators: error against run time (CRLB is exact: shown at 1e-4)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    return save_figure(fig, path, tight=True)


def plot_learning_curves(summary: dict, path) -> Path | None:
    """Each requirement's learner at DENALI's design against its training captures (``denali_point``'s
    ``learning_curve``: mean and 95 % interval), the run's own budget marked, DENALI's real Table 1 figure and the
    requirement as lines. None (nothing drawn) when no row has a curve of two points or more."""
    rows = [r for r in summary.get("denali_point", []) if len(r.get("learning_curve") or []) >= 2]
    if not rows:
        return None
    plt = pyplot()
    fig, axs = plt.subplots(1, len(rows), figsize=(4.4 * len(rows), 3.4), squeeze=False)
    for ax, r in zip(axs.flat, rows):
        pts = r["learning_curve"]
        n = [p["train_captures"] for p in pts]
        ax.errorbar(n, [p["value"] for p in pts], yerr=[[p["value"] - p["lo"] for p in pts],
                                                        [p["hi"] - p["value"] for p in pts]],
                    fmt="-o", color="C3", ms=4, capsize=2, label=f"{r['learner']} (95 % interval)")
        own = [p for p in pts if p["run_budget"]]
        if own:
            ax.plot([own[0]["train_captures"]], [own[0]["value"]], "s", color="k", ms=7, mfc="none",
                    label="the run's budget (every design)")
        if r.get("real") is not None:
            ax.axhline(r["real"], color="C0", lw=1.2, label="DENALI real (Table 1, 25,200 captures)")
        ax.axhline(r["threshold"], color="0.4", lw=1, ls=":", label="requirement")
        ax.set_xscale("log")
        ax.set_xlabel("training captures")
        ax.set_ylabel(_ylabel(r["requirement"]))
        ax.set_title(r["requirement"], fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    return save_figure(fig, path, tight=True)
