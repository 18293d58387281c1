"""Report of the active-vs-raster study: table (text, Markdown), curves figure, JSON."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from nlosplan.files import write_json, write_text
from nlosplan.reports.figures import pyplot, save_figure
from nlosplan.reports.tables import format_table

__all__ = ["active_rows", "active_text", "plot_active", "write_active"]


def _n(v, fmt="{:.0f}") -> str:
    return "n/r" if v is None else fmt.format(v)


def _iv(iv, fmt="{:.0f}") -> str:
    lo, hi = iv
    return "n/r" if lo is None else f"{fmt.format(lo)}–{_n(hi, fmt)}"


def active_rows(result: dict) -> list[dict]:
    """One display row per strategy (medians over seeds, [min–max] intervals; n/r: not reached in budget)."""
    rows = []
    for s in result["strategies"]:
        c = s["calibration"]
        row = {"strategy": s["name"]}
        targets = s.get("targets") or [{"target_rmse_m": result["config"]["target_rmse_m"], **s}]
        for t in targets:
            mm = f"{1e3 * t['target_rmse_m']:g} mm"
            row[f"captures to {mm}"] = f"{_n(t['captures_to_target'])} [{_iv(t['interval'])}]"
            row[f"gantry s to {mm}"] = f"{_n(t['gantry_seconds_to_target'])} [{_iv(t['gantry_interval'])}]"
        rows.append({**row,
                     "calib captures": f"{_n(c['captures_to_target'])} [{_iv(c['interval'])}]",
                     "calib gantry s": f"{_n(c['gantry_seconds_to_target'])} [{_iv(c['gantry_interval'])}]",
                     "run s": f"{s['seconds']:.0f}"})
    return rows


def _header(result: dict) -> str:
    cfg = result["config"]
    ratio = result.get("ratio_best_to_raster")
    head = (f"active vs raster: {cfg['obj']} {cfg['size']}, {cfg['sensor']}, {result['candidates']} candidates "
            f"({cfg['grid']}x{cfg['grid']}), batches of {cfg['batch_size']}, budget {cfg['budget']}, seeds "
            f"{','.join(str(s) for s in cfg['seeds'])}; targets: localization RMSE <= "
            f"{', '.join(f'{1e3 * t:g}' for t in sorted({cfg['target_rmse_m'], *cfg.get('more_targets_m', ())}))}"
            f" mm on {cfg['test_points']} test positions, calibration error <= {cfg['target_calibration']:g} tolerance")
    for target, r in (ratio or {}).items():
        head += (f"\nlocalization RMSE <= {1e3 * float(target):g} mm: " + (
            "n/r" if r is None else f"best strategy ({r['best']}) needs {r['ratio']:.2f} x the raster's captures "
                                    f"({r['captures']:.0f} vs {r['raster_captures']:.0f}, medians)"))
    return head


def active_text(result: dict) -> str:
    """Header and table for the terminal."""
    return (_header(result) + "\n" + format_table(active_rows(result))
            + "\nmedian [min–max] over seeds; n/r: not reached within the budget (by some seed, for an upper end)")


def active_markdown(result: dict, figure: str | None = None) -> str:
    """The table as Markdown, with the figure when given."""
    rows = active_rows(result)
    cols = list(rows[0])
    lines = ["| " + " | ".join(cols) + " |", "|" + "---|" * len(cols)]
    lines += ["| " + " | ".join(str(r[c]) for c in cols) + " |" for r in rows]
    out = _header(result).replace("\n", "\n\n") + "\n\n" + "\n".join(lines)
    return out + (f"\n\n![active vs raster]({figure})\n" if figure else "\n")


def _mean_curve(runs: list, key: str, budget: int) -> tuple[np.ndarray, np.ndarray]:
    """Mean over seeds of a metric against captures (runs stopped early keep their last value)."""
    xs = sorted({row["captures"] for r in runs for row in r["curve"]})
    ys = []
    for r in runs:
        cur = {row["captures"]: row[key] for row in r["curve"]}
        last, vals = np.nan, []
        for x in xs:
            last = cur.get(x, last)
            vals.append(last)
        ys.append(vals)
    return np.asarray(xs), np.nanmean(np.asarray(ys, dtype=float), axis=0)


def plot_active(result: dict, path) -> Path:
    """Localization RMSE and calibration error against captures and gantry time, one line per strategy."""
    plt = pyplot()
    cfg = result["config"]
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4))
    for k, name in enumerate(cfg["strategies"]):
        runs = [r for r in result["runs"] if r["strategy"] == name]
        style = {"color": f"C{k}", "lw": 2.2 if name == "raster" else 1.6, "ls": "--" if name == "raster" else "-"}
        x, y = _mean_curve(runs, "rmse_m", cfg["budget"])
        axes[0].plot(x, 1e3 * y, label=name, **style)
        xt, yt = _mean_curve(runs, "gantry_seconds", cfg["budget"])
        axes[1].plot(yt / 60.0, 1e3 * y, label=name, **style)
        xc, yc = _mean_curve(runs, "calibration_error", cfg["budget"])
        axes[2].plot(xc, yc, label=name, **style)
    axes[0].axhline(1e3 * cfg["target_rmse_m"], color="k", lw=0.8, ls=":")
    axes[1].axhline(1e3 * cfg["target_rmse_m"], color="k", lw=0.8, ls=":")
    axes[2].axhline(cfg["target_calibration"], color="k", lw=0.8, ls=":")
    axes[0].set(xlabel="captures", ylabel="localization RMSE (mm)", yscale="log", title="localization (test set)")
    axes[1].set(xlabel="gantry time (min: moves + settle + capture)", ylabel="localization RMSE (mm)", yscale="log",
                title="localization against gantry time")
    axes[2].set(xlabel="captures", ylabel="calibration error (x tolerance)", yscale="log",
                title="calibration (0.5 mm, 0.5 mm, 1 %, 1 %)")
    axes[0].legend(fontsize=8)
    fig.suptitle(f"Capture planning on the simulated DENALI rig ({cfg['obj']} {cfg['size']}, mean of "
                 f"{len(cfg['seeds'])} seeds; dotted: targets)", fontsize=10)
    return save_figure(fig, path, tight=True)


def write_active(result: dict, out_dir, *, plot=None) -> dict[str, str]:
    """Write active_vs_raster.json, .md and the figure; returns their paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    png = Path(plot) if plot else out / "active_vs_raster.png"
    plot_active(result, png)
    write_text(out / "active_vs_raster.md", active_markdown(result, png.name if png.parent == out else str(png)))
    write_json(out / "active_vs_raster.json", result, indent=1, default=float)
    return {"json": str(out / "active_vs_raster.json"), "markdown": str(out / "active_vs_raster.md"),
            "plot": str(png)}
