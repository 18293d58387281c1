"""Text of the realism checks: per-zone scores on real plane captures against the targets of issue 16."""

from __future__ import annotations


def plane_summary(zones: list[dict]) -> dict:
    """All-zone summary of per-zone rows: mean of the mean sub-bin errors and L1s, worst L1, amplitude range."""
    return {"subbin_err_mean": sum(z["subbin_err_mean"] for z in zones) / len(zones),
            "l1_mean": sum(z["l1_mean"] for z in zones) / len(zones),
            "l1_max": max(z["l1_max"] for z in zones),
            "amp_ratio_min": min(z["amp_ratio_min"] for z in zones),
            "amp_ratio_max": max(z["amp_ratio_max"] for z in zones)}


def format_plane_table(zones: list[dict], targets: dict, title: str = "") -> str:
    """One line per zone (sub-bin peak error, peak-bin error, L1 mean/max, amplitude range), the summary and verdicts.

    Parameters
    ----------
    zones : list of dict
        Rows as :func:`nlosplan.calibration.plane_scores.tables_dict` makes them.
    targets : dict
        ``subbin_err_mean``, ``l1_mean``, ``l1_max``, ``amp_ratio_min``, ``amp_ratio_max``.
    """
    from nlosplan.reports.tables import format_table

    def mark(ok: bool) -> str:
        return "" if ok else " *"

    rows = []
    for z in zones:
        m = z.get("meets", {})
        rows.append({"zone": z["zone"], "captures": z["n"],
                     "sub-bin err": f"{z['subbin_err_mean']:.3f}{mark(m.get('subbin_err_mean', True))}",
                     "(signed)": f"{z['subbin_err_signed']:+.3f}",
                     "peak-bin err": f"{z['peak_bin_err_mean']:.2f}",
                     "L1 mean": f"{100 * z['l1_mean']:.1f} %{mark(m.get('l1_mean', True))}",
                     "L1 max": f"{100 * z['l1_max']:.1f} %{mark(m.get('l1_max', True))}",
                     "amp pred/meas": f"{z['amp_ratio_min']:.2f}-{z['amp_ratio_max']:.2f}{mark(m.get('amp_ratio', True))}"})
    s = plane_summary(zones)
    t = targets
    verdict = {
        "sub-bin error": s["subbin_err_mean"] <= t["subbin_err_mean"],
        "L1 mean": s["l1_mean"] <= t["l1_mean"],
        "L1 max": s["l1_max"] <= t["l1_max"],
        "amplitude": t["amp_ratio_min"] <= s["amp_ratio_min"] and s["amp_ratio_max"] <= t["amp_ratio_max"],
    }
    lines = [title] if title else []
    lines.append(format_table(rows))
    lines.append(f"all zones: sub-bin error {s['subbin_err_mean']:.3f} bin (target <= {t['subbin_err_mean']:g}), "
                 f"L1 mean {100 * s['l1_mean']:.1f} % (<= {100 * t['l1_mean']:g} %), max {100 * s['l1_max']:.1f} % "
                 f"(<= {100 * t['l1_max']:g} %), amplitude {s['amp_ratio_min']:.2f}-{s['amp_ratio_max']:.2f} "
                 f"(within {t['amp_ratio_min']:g}-{t['amp_ratio_max']:g})")
    lines.append("targets: " + ", ".join(f"{k} {'met' if ok else 'NOT met'}" for k, ok in verdict.items())
                 + ("" if all(verdict.values()) else "   (* marks the zones that miss)"))
    return "\n".join(lines)


def format_table2(res: dict, title: str = "") -> str:
    """One line per statistics row (model / real per statistic, * where a target is missed), the ratios, the levels.

    Parameters
    ----------
    res : dict
        As :func:`nlosplan.calibration.stats_score.score_stats` returns it.
    """
    from nlosplan.reports.tables import format_table

    def cell(r, s, fmt):
        mark = "" if r["meets"][s] else " *"
        return f"{fmt.format(r[s])} / {fmt.format(r['real'][s])}{mark}"

    rows = [{"row": f"{r['zones']} {r['light']} {r['size']}", "total (model / real)": cell(r, "total", "{:.0f}"),
             "centroid": cell(r, "centroid", "{:.2f}"), "spread": cell(r, "spread", "{:.2f}"),
             "skew": cell(r, "skew", "{:+.2f}"),
             "MC +-": f"{r['mc_std']['total']:.0f} / {r['mc_std']['centroid']:.2f}"} for r in res["rows"]]
    t = res["targets"]
    lines = [title] if title else []
    lines.append(format_table(rows))
    if res["ratios"]:
        lines.append("ratios of totals (model / real): " + ", ".join(
            f"{k} {v['model']:.2f} / {v['real']:.2f}{'' if v['meets'] else ' *'}" for k, v in res["ratios"].items()))
    if res.get("levels"):
        lines.append("levels (model / real): " + ", ".join(f"{k} {v['model']:.4g} / {v['real']:.4g}"
                                                          for k, v in res["levels"].items()))
    m = res["meets"]
    lines.append(f"targets (total +-{100 * t['total_rel']:g} %, centroid +-{t['centroid_bins']:g} bin, spread "
                 f"+-{100 * t['spread_rel']:g} %, skew sign, ratios +-{100 * t['ratio_rel']:g} %): "
                 f"{m['statistics']} of {m['statistics_of']} row statistics and {m['ratios']} of {m['ratios_of']} "
                 f"ratios met (* marks a miss); {res['n_scenes']} scenes per row, {len(res['seeds'])} noise seeds")
    return "\n".join(lines)
