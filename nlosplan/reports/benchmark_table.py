"""The benchmark result (:func:`nlosplan.tasks.benchmark.run_benchmark`) as the paper's table.

Layout: models as rows; per task its metrics, overall and by group, as
columns (localization: RMSE/MAE overall, by size, by class group; shape:
top-1/top-5/macro F1 overall, by near/far quadrant, by size; size:
precision/recall/accuracy overall, by quadrant, by class group). Errors are
in metres, accuracies in percent. Formats: a pandas table
(:func:`benchmark_table`), text for the terminal, Markdown and CSV files.
"""

from __future__ import annotations

from pathlib import Path

import pandas as pd

from nlosplan.files import write_json, write_text

from nlosplan.reports.tables import markdown_table

__all__ = ["benchmark_markdown", "benchmark_table", "benchmark_text", "not_applicable", "runs_table", "write_benchmark"]

TASK_TITLES = {"loc": "Localization (x, y), metres", "shape": "Shape classification (30-way), %",
               "size": "Size classification (4 in vs 8 in), %"}
_METRIC_LABELS = {"loc_rmse": "RMSE", "mae": "MAE", "top1_acc": "Top-1", "top5_acc": "Top-5", "macro_f1": "F1",
                  "macro_precision": "Precision", "macro_recall": "Recall"}


def _metric_label(task: str, metric: str) -> str:
    return "Accuracy" if (task == "size" and metric == "top1_acc") else _METRIC_LABELS.get(metric, metric)


def _ordered(values, first) -> list:
    seen = list(dict.fromkeys(values))
    return [v for v in first if v in seen] + [v for v in seen if v not in first]


def benchmark_table(result: dict, task: str | None = None) -> pd.DataFrame:
    """Models as rows, (task, metric, group) as columns, raw values (metres, fractions).

    Parameters
    ----------
    result : dict
        From :func:`~nlosplan.tasks.benchmark.run_benchmark`.
    task : str, optional
        Only this task's columns (then the columns are (metric, group)).

    Returns
    -------
    pandas.DataFrame
        Index ``model`` in the run's order; columns in table order: the
        overall metrics, then the same metrics for each group.
    """
    rows = pd.DataFrame(result["rows"], columns=["model", "task", "metric", "group_by", "group", "value", "n"])
    if task is not None:
        rows = rows[rows["task"] == task]
    if rows.empty:
        return pd.DataFrame(index=pd.Index([], name="model"))
    models = _ordered(rows["model"], result["config"]["models"])
    cols = list(dict.fromkeys(zip(rows["task"], rows["metric"], rows["group"])))  # group-major, as computed
    order_tasks = _ordered(rows["task"], result["config"]["tasks"])
    cols.sort(key=lambda c: order_tasks.index(c[0]))  # stable: keeps the order inside a task
    wide = rows.pivot_table(index="model", columns=["task", "metric", "group"], values="value", aggfunc="first")
    table = wide.reindex(index=models, columns=pd.MultiIndex.from_tuples(cols, names=["task", "metric", "group"]))
    return table.droplevel("task", axis=1) if task is not None else table


def runs_table(result: dict) -> pd.DataFrame:
    """One row per (model, task): status, epochs, stop reason, training seconds, parameters."""
    cols = ["model", "task", "status", "epochs_run", "best_epoch", "stopped", "train_seconds", "seconds_per_epoch",
            "n_train", "n_val", "n_test", "n_params", "lr", "batch_size", "reason"]
    return pd.DataFrame(result["runs"]).reindex(columns=cols)


def _display(task: str, value: float) -> str:
    if pd.isna(value):
        return ""
    return f"{value:.4f}" if task == "loc" else f"{100 * value:.1f}"


def _task_block(result: dict, task: str) -> pd.DataFrame:
    """One task's table, formatted: models as rows, "<metric> <group>" columns, plus training time."""
    t = benchmark_table(result, task)
    out = pd.DataFrame(index=t.index)
    for metric, group in t.columns:
        label = _metric_label(task, metric) + ("" if group == "all" else f" {group}")
        out[label] = [_display(task, v) for v in t[(metric, group)]]
    runs = runs_table(result)
    runs = runs[(runs["task"] == task)].set_index("model")
    out["train s"] = [f"{runs.loc[m, 'train_seconds']:.0f}" if m in runs.index and runs.loc[m, "status"] == "ok"
                      else "" for m in out.index]
    out["epochs"] = [str(int(runs.loc[m, "epochs_run"])) if m in runs.index and runs.loc[m, "status"] == "ok"
                     else "" for m in out.index]
    return out


def _header(result: dict) -> str:
    c = result["config"]
    shape = "x".join(str(v) for v in c["histogram_shape"])
    return (f"DENALI benchmark: split {c['split']}, seed {c['seed']}, profile {c['profile']}, width {c['width']:g}, "
            f"epochs {c['epochs'] if c['epochs'] is not None else 'default'}, {c['n_rows']} rows "
            f"({'mean of repeats' if c['average_repeats'] else 'repeats kept'}), histograms {shape}, "
            f"{result['seconds']:.0f} s")


def not_applicable(result: dict) -> list[str]:
    """A line per task whose entries did not run (e.g. a held-out split that does not apply), with the reason."""
    seen = {}
    for r in result["runs"]:
        if r.get("status") != "ok":
            seen.setdefault(r["task"], r.get("reason", ""))
    return [f"{task}: n/a ({why})" for task, why in seen.items()]


def _task_block_text(result: dict, task: str) -> pd.DataFrame:
    """One task for the terminal: a row per (model, metric), a column per group, then training time."""
    t = benchmark_table(result, task)
    groups = list(dict.fromkeys(g for _, g in t.columns))
    metrics = list(dict.fromkeys(m for m, _ in t.columns))
    runs = runs_table(result)
    runs = runs[runs["task"] == task].set_index("model")
    lines = []
    for model in t.index:
        for i, metric in enumerate(metrics):
            row = {"model": model if i == 0 else "", "metric": _metric_label(task, metric)}
            row.update({g: _display(task, t[(metric, g)].get(model)) if (metric, g) in t.columns else ""
                        for g in groups})
            ok = i == 0 and model in runs.index and runs.loc[model, "status"] == "ok"
            row["train s"] = f"{runs.loc[model, 'train_seconds']:.0f}" if ok else ""
            row["epochs"] = str(int(runs.loc[model, "epochs_run"])) if ok else ""
            lines.append(row)
    return pd.DataFrame(lines)


def _title(result: dict, task: str) -> str:
    n = result["config"].get("n_classes", {}).get(task)
    return TASK_TITLES[task] if (task != "shape" or n is None) else TASK_TITLES[task].replace("30-way", f"{n}-way")


def benchmark_text(result: dict) -> str:
    """The table for the terminal: a block per task (a row per model and metric, a column per group)."""
    lines = [_header(result)]
    for task in result["config"]["tasks"]:
        if not any(r["task"] == task for r in result["rows"]):
            continue
        lines += ["", _title(result, task), _task_block_text(result, task).to_string(index=False)]
    na = not_applicable(result)
    if na:
        lines += [""] + na
    return "\n".join(lines)


def benchmark_markdown(result: dict) -> str:
    """Markdown: the settings, a table per task (models as rows) and the training runs."""
    parts = ["# DENALI benchmark", "", _header(result)]
    for task in result["config"]["tasks"]:
        if not any(r["task"] == task for r in result["rows"]):
            continue
        parts += ["", f"## {_title(result, task)}", "", markdown_table(_task_block(result, task).reset_index())]
    runs = runs_table(result)
    shown = runs.assign(train_seconds=runs["train_seconds"].map(lambda v: "" if pd.isna(v) else f"{v:.1f}"),
                        seconds_per_epoch=runs["seconds_per_epoch"].map(lambda v: "" if pd.isna(v) else f"{v:.2f}"))
    parts += ["", "## Training runs", "", markdown_table(shown.fillna(""))]
    return "\n".join(parts) + "\n"


def write_benchmark(result: dict, out_dir) -> dict[str, str]:
    """Write ``benchmark.csv`` (models as rows, ``task/metric/group`` columns, raw values and training
    seconds), ``benchmark.md`` and ``benchmark.json`` (the whole result) into ``out_dir``.

    Returns
    -------
    dict
        ``{"csv": path, "markdown": path, "json": path}``.
    """
    out = Path(out_dir)
    table = benchmark_table(result)
    flat = pd.DataFrame(table.to_numpy(), index=table.index, columns=["/".join(c) for c in table.columns])
    runs = runs_table(result)
    for task in result["config"]["tasks"]:
        r = runs[runs["task"] == task].set_index("model")
        flat[f"{task}/train_seconds"] = [r["train_seconds"].get(m) for m in flat.index]
    paths = {"csv": out / "benchmark.csv", "markdown": out / "benchmark.md", "json": out / "benchmark.json"}
    write_text(paths["csv"], flat.to_csv(index_label="model"))
    write_text(paths["markdown"], benchmark_markdown(result))
    write_json(paths["json"], result, indent=2, default=float)
    return {k: str(v) for k, v in paths.items()}
