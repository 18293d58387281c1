"""The jitter study (:func:`nlosplan.experiments.jitter.run_jitter_study`) as a figure and tables.

Figure: one panel per task, one line per model, jitter FWHM on the x axis
(the levels evenly spaced, labelled in ps): localization RMSE in cm, shape
top-1 accuracy in %, size accuracy in %; the chance level of each
classification task (1 / number of classes) is drawn dashed.

Tables: jitter levels as rows, per model the overall metrics of each task
as columns (localization RMSE and MAE in metres, classification metrics in
percent): :func:`jitter_table` (raw values, pandas), :func:`jitter_text`
(terminal), :func:`jitter_markdown`; :func:`write_jitter` writes the CSV,
Markdown, JSON and PNG files. Computes no results.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from nlosplan.files import write_json, write_text

from nlosplan.reports.benchmark_table import not_applicable
from nlosplan.reports.figures import pyplot, save_figure
from nlosplan.reports.tables import markdown_table

__all__ = ["METRIC_ORDER", "jitter_markdown", "jitter_table", "jitter_text", "levels_table", "plot_jitter",
           "write_jitter"]

#: Metrics shown per task, in table order (the study's: RMSE/MAE; top-1/top-5/F1; accuracy/precision/recall).
METRIC_ORDER: dict[str, tuple[str, ...]] = {"loc": ("loc_rmse", "mae"), "shape": ("top1_acc", "top5_acc", "macro_f1"),
                                            "size": ("top1_acc", "macro_precision", "macro_recall")}
_LABELS = {("loc", "loc_rmse"): "loc RMSE m", ("loc", "mae"): "loc MAE m", ("shape", "top1_acc"): "shape top-1 %",
           ("shape", "top5_acc"): "shape top-5 %", ("shape", "macro_f1"): "shape F1 %",
           ("size", "top1_acc"): "size acc %", ("size", "macro_precision"): "size prec %",
           ("size", "macro_recall"): "size rec %"}
#: What each panel of the figure shows: (task, metric, y label, scale to display units).
PANELS = {"loc": ("loc_rmse", "localization RMSE (cm)", 100.0), "shape": ("top1_acc", "shape top-1 accuracy (%)", 100.0),
          "size": ("top1_acc", "size accuracy, 4 in vs 8 in (%)", 100.0)}
_TITLES = {"loc": "Localization", "shape": "Shape ({n}-way)", "size": "Size (4 in vs 8 in)"}


def _rows(result: dict) -> pd.DataFrame:
    cols = ["jitter_ps", "model", "task", "metric", "group_by", "group", "value", "n"]
    rows = pd.DataFrame(result["rows"], columns=cols)
    return rows[rows["group"] == "all"]


def jitter_table(result: dict) -> pd.DataFrame:
    """Jitter levels as rows, (model, task, metric) as columns, overall values (metres, fractions).

    Parameters
    ----------
    result : dict
        From :func:`~nlosplan.experiments.jitter.run_jitter_study`.

    Returns
    -------
    pandas.DataFrame
        Index ``jitter_ps`` (ascending, ps); columns a MultiIndex
        ``(model, task, metric)`` in the study's model and task order and
        :data:`METRIC_ORDER`; entries that did not run (status n/a) are NaN.
    """
    c = result["config"]
    rows = _rows(result)
    levels = sorted(float(v) for v in c["jitter_ps"])
    cols = [(m, t, k) for m in c["models"] for t in c["tasks"] for k in METRIC_ORDER[t]]
    index = pd.Index(levels, name="jitter_ps")
    if rows.empty:
        return pd.DataFrame(index=index, columns=pd.MultiIndex.from_tuples(cols, names=["model", "task", "metric"]))
    wide = rows.pivot_table(index="jitter_ps", columns=["model", "task", "metric"], values="value", aggfunc="first")
    return wide.reindex(index=index, columns=pd.MultiIndex.from_tuples(cols, names=["model", "task", "metric"]))


def levels_table(result: dict) -> pd.DataFrame:
    """One row per jitter level: rows trained on, the blurred histograms' peak and width, and the timings."""
    cols = ["jitter_ps", "n_rows", "peak_counts", "peak_width_ps", "total_counts", "jitter_seconds",
            "train_seconds", "seconds"]
    return pd.DataFrame(result["levels"]).reindex(columns=cols)


def _display(task: str, value) -> str:
    if pd.isna(value):
        return "n/a"
    return f"{value:.4f}" if task == "loc" else f"{100 * value:.1f}"


def _model_block(result: dict, model: str) -> pd.DataFrame:
    """One model, formatted: a row per jitter level, a column per task metric, training seconds."""
    table = jitter_table(result)
    out = pd.DataFrame({"jitter ps": [f"{v:g}" for v in table.index]})
    for (m, task, metric) in table.columns:
        if m == model:
            out[_LABELS.get((task, metric), f"{task} {metric}")] = [_display(task, v) for v in table[(m, task, metric)]]
    runs = pd.DataFrame(result["runs"]).reindex(columns=["jitter_ps", "model", "train_seconds"])
    secs = runs[runs["model"] == model].groupby("jitter_ps")["train_seconds"].sum(min_count=1)
    out["train s"] = [f"{secs[v]:.1f}" if v in secs.index and pd.notna(secs[v]) else "" for v in table.index]
    return out


def _header(result: dict) -> str:
    c = result["config"]
    shape = "x".join(str(v) for v in c["histogram_shape"])
    given = "x".join(str(v) for v in c["histogram_shape_given"])
    zone = "centre zone" if c["zone"] == "centre" else "all zones"
    return (f"DENALI jitter study: {zone} ({shape} of {given}), jitter FWHM "
            f"{', '.join(f'{v:g}' for v in c['jitter_ps'])} ps (bin width {c['bin_width_ps']:.4g} ps); "
            f"{c['n_scenes']} scenes from {c['n_captures']} captures "
            f"({'mean of repeats' if c['average_repeats'] else 'repeats kept'}); split {c['split']}, seed {c['seed']}, "
            f"profile {c['profile']}, width {c['width']:g}, "
            f"epochs {c['epochs'] if c['epochs'] is not None else 'default'}; {result['seconds']:.0f} s")


def _levels_display(result: dict) -> pd.DataFrame:
    lv = levels_table(result)
    return pd.DataFrame({"jitter ps": lv["jitter_ps"].map("{:g}".format), "rows": lv["n_rows"],
                         "peak counts": lv["peak_counts"].map("{:.4g}".format),
                         "peak width ps": lv["peak_width_ps"].map("{:.0f}".format),
                         "jitter s": lv["jitter_seconds"].map("{:.2f}".format),
                         "train s": lv["train_seconds"].map("{:.1f}".format),
                         "total s": lv["seconds"].map("{:.1f}".format)})


def jitter_text(result: dict) -> str:
    """The study for the terminal: the settings, a block per model (jitter rows, metric columns), the levels."""
    lines = [_header(result)]
    for model in result["config"]["models"]:
        lines += ["", f"{model} (localization in m, classification in %)",
                  _model_block(result, model).to_string(index=False)]
    lines += ["", "levels (histograms fed to training: mean highest bin, width of the direct peak; timings)",
              _levels_display(result).to_string(index=False)]
    na = not_applicable(result)
    return "\n".join(lines + ([""] + na if na else []))


def jitter_markdown(result: dict, *, figure: str | None = None) -> str:
    """Markdown: the settings, a table per model (jitter rows, metric columns), the levels, the figure."""
    parts = ["# DENALI jitter study", "", _header(result)]
    if figure:
        parts += ["", f"![jitter study]({figure})"]
    for model in result["config"]["models"]:
        parts += ["", f"## {model}", "", "Localization in metres, classification in percent.", "",
                  markdown_table(_model_block(result, model), align="---:")]
    parts += ["", "## Levels", "", "Histograms fed to training (mean highest bin, width of the direct peak) "
              "and timings.", "", markdown_table(_levels_display(result), align="---:")]
    na = not_applicable(result)
    if na:
        parts += ["", *[f"- {line}" for line in na]]
    return "\n".join(parts) + "\n"


def plot_jitter(result: dict, path, *, title: str | None = None):
    """Write the study's figure: a panel per task, a line per model, metric against jitter FWHM.

    Parameters
    ----------
    result : dict
        From :func:`~nlosplan.experiments.jitter.run_jitter_study`.
    path : str or Path
        Output PNG (parent folders are created).
    title : str, optional
        Figure title (default: the zone view, scenes, split and seed).

    Returns
    -------
    Path
        The written file.

    Notes
    -----
    The jitter levels are placed evenly along x (labelled with their FWHM in
    ps), so that 0, 50 and 100 ps stay apart next to 600 ps. Chance: 1 / the
    number of classes for shape (1/30 on DENALI's objects), 1/2 for size.
    """
    plt = pyplot()
    c = result["config"]
    tasks = [t for t in c["tasks"] if t in PANELS]
    table = jitter_table(result)
    levels = list(table.index)
    xs = list(range(len(levels)))
    fig, axes = plt.subplots(1, len(tasks), figsize=(4.3 * len(tasks), 4.0), squeeze=False)
    markers = "osD^v<>p"
    for ax, task in zip(axes[0], tasks):
        metric, ylabel, scale = PANELS[task]
        drawn = False
        for i, model in enumerate(c["models"]):
            key = (model, task, metric)
            if key not in table.columns or table[key].isna().all():
                continue
            ys = (table[key] * scale).tolist()
            ax.plot(xs, ys, marker=markers[i % len(markers)], color=f"C{i}", lw=1.5, ms=6, label=model)
            drawn = True
        n_classes = (c.get("n_classes") or {}).get(task)
        if task != "loc" and n_classes:
            chance = 100.0 / n_classes
            ax.axhline(chance, color="0.45", ls="--", lw=1.0, label=f"chance (1/{n_classes})")
        if task == "loc":
            ax.set_ylim(bottom=0, top=max(ax.get_ylim()[1] * 1.1, 1.0))
        else:
            ax.set_ylim(0, 102)
        if not drawn:
            ax.text(0.5, 0.5, "n/a for this split", transform=ax.transAxes, ha="center", va="center", color="0.4")
        ax.set_xticks(xs)
        ax.set_xticklabels([f"{v:g}" for v in levels])
        ax.set_xlim(-0.3, len(xs) - 0.7)
        ax.set_xlabel("jitter FWHM (ps; levels evenly spaced)")
        ax.set_ylabel(ylabel)
        ax.set_title(_TITLES[task].format(n=n_classes or "?"), fontsize=10)
        ax.grid(True, lw=0.4, alpha=0.5)
        ax.legend(fontsize=8, loc="best")
    if title is None:
        zone = "centre zone" if c["zone"] == "centre" else "all zones"
        title = (f"Timing jitter at training and test: {zone}, {c['n_scenes']} scenes, split {c['split']}, "
                 f"seed {c['seed']} (bin width {c['bin_width_ps']:.3g} ps)")
    fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    return save_figure(fig, path, dpi=120)


def write_jitter(result: dict, out_dir, *, plot=None) -> dict[str, str]:
    """Write ``jitter.csv``, ``jitter.md``, ``jitter.json`` and the figure into ``out_dir``.

    Parameters
    ----------
    result : dict
        From :func:`~nlosplan.experiments.jitter.run_jitter_study`.
    out_dir : str or Path
        Output folder (created).
    plot : str or Path, optional
        Figure path (default ``out_dir / "jitter.png"``).

    Returns
    -------
    dict
        ``{"csv", "markdown", "json", "plot"}`` -> path. The CSV has a row
        per jitter level (``jitter_ps``), ``model/task/metric`` columns of
        overall values (metres, fractions) and the level's histogram summary
        and seconds; the JSON is the whole result.
    """
    out = Path(out_dir)
    paths = {"csv": out / "jitter.csv", "markdown": out / "jitter.md", "json": out / "jitter.json",
             "plot": Path(plot) if plot is not None else out / "jitter.png"}
    table = jitter_table(result)
    flat = pd.DataFrame(table.to_numpy(), index=table.index, columns=["/".join(col) for col in table.columns])
    lv = levels_table(result).set_index("jitter_ps")
    for col in ("n_rows", "peak_counts", "peak_width_ps", "train_seconds", "seconds"):
        flat[col] = [lv[col].get(v) for v in flat.index]
    write_text(paths["csv"], flat.to_csv(index_label="jitter_ps"))
    plot_jitter(result, paths["plot"])
    try:
        figure = str(Path(paths["plot"]).resolve().relative_to(out.resolve()))
    except ValueError:
        figure = str(Path(paths["plot"]).resolve())
    write_text(paths["markdown"], jitter_markdown(result, figure=figure))
    write_json(paths["json"], result, indent=2, default=float)
    return {k: str(v) for k, v in paths.items()}
