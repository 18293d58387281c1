"""The design report's "How real is this model" section: the shipped real-data scores as one table.

Self-contained: it reads :func:`nlosplan.calibration.realism.shipped_realism`
(what ``nlosplan bench real`` measured for the calibrated presets) and never
reruns a calibration.
"""

from __future__ import annotations

import pandas as pd

TITLE = "How real is this model"


def _yes(ok: bool) -> str:
    return "yes" if ok else "NO"


def realism_rows(shipped: dict) -> pd.DataFrame:
    """One row per checked figure: check, preset, figure, model, real or target, met (``yes``/``NO``).

    Parameters
    ----------
    shipped : dict
        As :func:`~nlosplan.calibration.realism.shipped_realism` returns it.
    """
    rows = []
    p = shipped.get("plane")
    if p:
        s, t = p["summary"], p["targets"]
        amp_ok = t["amp_ratio_min"] <= s["amp_ratio_min"] and s["amp_ratio_max"] <= t["amp_ratio_max"]
        for fig, model, target, ok in (
                ("sub-bin peak error", f"{s['subbin_err_mean']:.3f} bin", f"<= {t['subbin_err_mean']:g}",
                 s["subbin_err_mean"] <= t["subbin_err_mean"]),
                ("shape L1, mean", f"{100 * s['l1_mean']:.1f} %", f"<= {100 * t['l1_mean']:g} %",
                 s["l1_mean"] <= t["l1_mean"]),
                ("shape L1, max", f"{100 * s['l1_max']:.1f} %", f"<= {100 * t['l1_max']:g} %",
                 s["l1_max"] <= t["l1_max"]),
                ("amplitude predicted/measured", f"{s['amp_ratio_min']:.2f}-{s['amp_ratio_max']:.2f}",
                 f"{t['amp_ratio_min']:g}-{t['amp_ratio_max']:g}", amp_ok)):
            rows.append({"check": "plane captures, held out", "preset": p["sensor"], "figure": fig, "model": model,
                         "real or target": target, "met": _yes(ok)})
    t2 = shipped.get("table2")
    if t2:
        fmt = {"total": "{:.0f}", "centroid": "{:.2f}", "spread": "{:.2f}", "skew": "{:+.2f}"}
        for r in t2["rows"]:
            for stat, f in fmt.items():
                rows.append({"check": f"DENALI Table 2, 3x3 {r['light']} {r['size']}", "preset": t2["sensor"],
                             "figure": stat, "model": f.format(r[stat]), "real or target": f.format(r["real"][stat]),
                             "met": _yes(r["meets"][stat])})
        for name, q in t2["ratios"].items():
            rows.append({"check": "DENALI Table 2, ratio of totals", "preset": t2["sensor"], "figure": name,
                         "model": f"{q['model']:.2f}", "real or target": f"{q['real']:.2f}", "met": _yes(q["meets"])})
    return pd.DataFrame(rows, columns=["check", "preset", "figure", "model", "real or target", "met"])


def realism_section(reference_sensor: str) -> tuple[str, str, pd.DataFrame]:
    """``(title, text, table)`` of the section, for the design whose reference sensor is ``reference_sensor``."""
    from nlosplan.calibration.realism import shipped_realism

    shipped = shipped_realism()
    df = realism_rows(shipped)
    checked = {shipped[k]["sensor"] for k in ("plane", "table2") if k in shipped}
    met, n = int((df["met"] == "yes").sum()), len(df)
    t2 = shipped.get("table2", {})
    tg = t2.get("targets", {})
    text = (f"The simulator against real data, as 'nlosplan bench real' measured it for the calibrated presets "
            f"({', '.join(sorted(checked))}): {met} of {n} figures meet issue 16's targets"
            + (f" (Table 2: total +-{100 * tg['total_rel']:g} %, centroid +-{tg['centroid_bins']:g} bin, spread "
               f"+-{100 * tg['spread_rel']:g} %, skew sign, ratios +-{100 * tg['ratio_rel']:g} %; noisy simulated "
               f"captures, DENALI's processing, {t2['n_scenes']} scenes per row)" if tg else "") + ". "
            + ("This design's reference sensor is one of them." if reference_sensor in checked else
               f"This design's reference sensor, {reference_sensor}, is not one of them: its levels are not checked "
               "against real data; these rows say how far the model's physics carries."))
    return TITLE, text, df
