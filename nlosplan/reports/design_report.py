"""The design report: ``report.md``, a self-contained ``report.html`` and the PNG plots beside them.

The first screen answers the question: first what the run predicts at DENALI's own design point beside
DENALI's real Table 1 (and, where a verdict disagrees, why), then for each requirement, its verdict
(met / not met / undecided), the cheapest design that meets it (with its
metric, interval, margin and the worlds it holds in) and why, then the
minimum requirement per parameter. Below: the metric definitions, the
learners, the worlds (what would change the answer), the trade-off curves,
Pareto fronts, the evaluators' error against run time and the
bound-to-trained gap, whether a learner beats its bound, failures and unreachable designs, the stability
catalog and provenance.
"""

from __future__ import annotations

import base64
import html
import json
import math
from pathlib import Path

import pandas as pd

from nlosplan.files import write_text
from nlosplan.reports.denali_section import (CONSISTENCY_TITLE, DENALI_TITLE, answer_note, budget_text,
                                             consistency_table, consistency_text, denali_point_table,
                                             curve_text, denali_point_text, disagreement_text)
from nlosplan.reports.design_plots import plot_evaluators, plot_learning_curves, plot_pareto, plot_tradeoffs
from nlosplan.reports.realism_section import realism_section
from nlosplan.reports.tables import format_table, markdown_table

__all__ = ["write_design_report", "requirements_table", "answer_table", "minimum_hardware_text", "learners_table",
           "worlds_table"]

_PARAM_FMT = {  # user units (summary.PARAMETERS): zones are already "RxC"
    "zones": str,
    "bin_width_ps": lambda v: f"{v:.0f} ps",
    "n_bins": lambda v: f"{v:.0f}",
    "jitter_fwhm_ps": lambda v: f"{v:.0f} ps",
    "pulse_fwhm_ps": lambda v: f"{v:.0f} ps",
    "photon_fraction": lambda v: f"{v:.3g}x",
}
#: How the verdicts read in tables ("NO" and "yes" are coloured in the HTML).
_VERDICT_TEXT = {"met": "yes", "not met": "NO", "undecided": "undecided"}


def _worlds_budget_text(result: dict) -> str:
    """The worlds' own budget, spent where one more seed could change the answer (empty for an old result)."""
    b = result.get("budget", {})
    if b.get("worlds_extra_evaluations") is None:
        return ""
    return (f" Every candidate gets one seed per world; {b['worlds_spent']} of {b['worlds_extra_evaluations']} extra "
            "world evaluations went to the candidate fewest worlds short of holding, in the worlds that more seeds "
            "could still turn met.")


def _fmt_metric(task: str, v) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    return f"{100 * v:.1f} cm" if task == "loc" else f"{100 * v:.1f} %"


def _design_text(d: dict | None, ref_bin_ps: float | None = None) -> str:
    if not d:
        return "none in the space"
    return (f"{d['zones']} zones, {d['n_bins']} bins of {d['bin_width_ps']:.0f} ps, jitter "
            f"{d['jitter_fwhm_ps']:.0f} ps, pulse +{d['pulse_fwhm_ps']:.0f} ps, {d['photon_fraction']:.3g}x photons")


def _worlds_text(c: dict) -> str:
    w = c.get("worlds")
    if not w:
        return "n/a"
    return f"{w['met']} of {w['worlds']} (needs {w['needed']})"


def answer_table(summary: dict, ref_bin_ps: float | None = None) -> pd.DataFrame:
    """One row per requirement: verdict, cheapest design, metric with interval, worlds held, margin, cost, why."""
    rows = []
    for c in summary["cheapest"]:
        task = c["task"]
        ok = c["design"] is not None
        rows.append({"requirement": c["requirement"], "met": _VERDICT_TEXT[c["verdict"]],
                     "cheapest design": _design_text(c["design"]) if ok else "none in the space",
                     "metric [95 % interval]": (f"{_fmt_metric(task, c['value'])} [{_fmt_metric(task, c['lo'])}, "
                                                f"{_fmt_metric(task, c['hi'])}]") if ok else "n/a",
                     "worlds held": _worlds_text(c),
                     "margin": f"{100 * c['margin']:+.0f} %" if ok else "n/a",
                     "cost": f"{c['cost']:.2f}" if ok else "n/a", "learner": c["learner"],
                     "from": c["source"], "why": _why(summary, c)})
    return pd.DataFrame(rows)


def _why(summary: dict, c: dict) -> str:
    """The answer's decision, and the sentence where it needs more than DENALI's hardware."""
    note = answer_note(summary, c["requirement"])
    return f"{c['decision'].rstrip('.')}. {note}" if note else c["decision"]


def requirements_table(summary: dict) -> pd.DataFrame:
    """One row per (requirement, parameter): verdict, least hardware along that axis, interval, note."""
    rows = []
    for r in summary["requirements"]:
        kind = "minimum" if "minimum" in r else "maximum"
        fmt = _PARAM_FMT[r["parameter"]]
        v = r[kind]
        rows.append({"requirement": r["requirement"], "parameter": r["label"], "verdict": r["verdict"],
                     "least hardware": f"{kind[:3]} {fmt(v)}" if v is not None else
                     ("undecided" if r["verdict"] == "undecided" else "not met"),
                     "95 % interval": (f"{fmt(r['interval'][0])} - {fmt(r['interval'][1])}"
                                       if r["interval"] else ""),
                     "note": r["note"]})
    return pd.DataFrame(rows)


def learners_table(summary: dict) -> pd.DataFrame:
    """Every candidate learner on the reference design, per task, and which one the run used."""
    rows = []
    for r in summary.get("learners", []):
        task = r["task"]
        rows.append({"task": task, "model": r["model"], "used": "yes" if r["chosen"] else "",
                     "metric [95 % interval]": (f"{_fmt_metric(task, r['value'])} [{_fmt_metric(task, r['lo'])}, "
                                                f"{_fmt_metric(task, r['hi'])}]") if r["value"] is not None else "n/a",
                     "seeds": r["seeds"], "s per run": (f"{r['seconds_per_run']:.1f}"
                                                        if r["seconds_per_run"] is not None else "n/a")})
    return pd.DataFrame(rows)


def worlds_table(summary: dict) -> pd.DataFrame:
    """Per requirement, each candidate examined in the worlds: held in, needed, what would change the answer."""
    rows = []
    for r in (summary.get("worlds") or {}).get("candidates", []):
        rows.append({"requirement": r["requirement"], "design": _design_text(r["design"]),
                     "cost": f"{r['cost']:.2f}",
                     "held in": "n/a" if r.get("met") is None else f"{r['met']} of {r['worlds']}",
                     "needed": r["needed"], "holds": "yes" if r["holds"] else "NO",
                     "what would change this answer": r["breaks"]})
    return pd.DataFrame(rows)


def world_parameters_table(summary: dict) -> pd.DataFrame:
    """The drawn worlds: one row per world, one column per parameter."""
    w = summary.get("worlds") or {}
    return pd.DataFrame([{"world": x["world"], **{k: f"{v:.4g}" for k, v in x["parameters"].items()}}
                         for x in w.get("worlds", [])])


def _definitions_text(summary: dict) -> str:
    return " ".join(f"**{k}**: {v}." for k, v in summary.get("metric_definitions", {}).items())


def minimum_hardware_text(summary: dict, ref_bin_ps: float | None = None) -> str:
    """The terminal table: the rows at DENALI's design point, the verdict and answer per requirement, then the
    per-parameter requirements."""
    a = answer_table(summary).drop(columns=["why"])
    why = "\n".join(f"  {c['requirement']}: {c['verdict']}: {_why(summary, c)}" for c in summary["cheapest"])
    r = requirements_table(summary)
    model = summary.get("world_model")
    world = f"\nsimulated world: sensor {model['sensor']}; scenes: {model['scene']}" if model else ""
    budget = budget_text(summary)
    world += f"\n{budget}" if budget else ""
    return (_denali_text(summary) + format_table(a.to_dict("records")) + "\n" + why + world
            + "\n\nminimum requirement per parameter (others at the "
            f"reference {summary['reference_sensor']}):\n" + format_table(r.to_dict("records"))
            + "\n\nloc_rmse: " + summary["metric_definitions"]["loc_rmse"])


def _denali_text(summary: dict) -> str:
    """The terminal's first lines: the rows at DENALI's design, the disagreement and the consistency, short."""
    if not summary.get("denali_point"):
        return ""
    t = denali_point_table(summary).drop(columns=["learner"])
    lines = [f"{DENALI_TITLE} (predicted by the learners in the simulated world; DENALI real: Table 1):",
             format_table(t.to_dict("records"))]
    for text in (curve_text(summary), disagreement_text(summary)):
        if text:
            lines.append(text)
    n = len(summary.get("consistency", []))
    lines.append("evaluators consistent: no learner beats its bound beyond its interval" if not n else
                 f"evaluators INCONSISTENT: {n} learner figure(s) beat their bound beyond their interval (report)")
    return "\n".join(lines) + "\n\nleast hardware per requirement:\n"


def _gap_rows(summary: dict) -> pd.DataFrame:
    rows = []
    for req, g in summary["gap"].items():
        if req.startswith("loc"):
            text = f"trained RMSE = {math.exp(g['value']):.1f}x the CRLB"
        else:
            text = f"logit(trained) = logit(ideal observer) {g['value']:+.2f}"
        rows.append({"requirement": req, "gap (median)": text, "designs": g["n"],
                     "spread (IQR)": f"{g['spread']:.2f}" if math.isfinite(g["spread"]) else "n/a"})
    return pd.DataFrame(rows)


def _evaluator_rows(summary: dict) -> pd.DataFrame:
    rows = []
    for e in summary["evaluators"]:
        fid = ", ".join(f"{k}={v}" for k, v in e["fidelity"].items())
        rows.append({"evaluator": e["evaluator"], "task": e["task"], "model": e.get("model", ""),
                     "evaluations": e["evaluations"],
                     "ok": e["ok"], "unreachable": e["unreachable"], "failed": e["failed"],
                     "median s": f"{e['median_seconds']:.3f}", "total s": f"{e['total_seconds']:.1f}",
                     "median 95 % half-interval": (f"{e['median_half_interval']:.4f}"
                                                   if math.isfinite(e["median_half_interval"]) else "n/a"),
                     "fidelity": fid})
    return pd.DataFrame(rows)


def _disagreement_rows(summary: dict) -> pd.DataFrame:
    rows = []
    for d in summary.get("disagreements", []):
        task = d["requirement"].split()[0]
        rows.append({"requirement": d["requirement"], "design": d["design"],
                     "real captures": f"{_fmt_metric(task, d['real'])} [{_fmt_metric(task, d['real_lo'])}, "
                                      f"{_fmt_metric(task, d['real_hi'])}]",
                     "simulated": f"{_fmt_metric(task, d['sim'])} [{_fmt_metric(task, d['sim_lo'])}, "
                                  f"{_fmt_metric(task, d['sim_hi'])}]",
                     "disagree": "YES" if d["disagree"] else "no"})
    return pd.DataFrame(rows)


def _headline(summary: dict, ref_bin_ps: float | None = None) -> str:
    parts = []
    for c in summary["cheapest"]:
        if c["verdict"] == "met":
            held = f", met in {_worlds_text(c)} worlds" if c.get("worlds") else ""
            parts.append(f"**{c['requirement']}**: met by {_design_text(c['design'])} "
                         f"({_fmt_metric(c['task'], c['value'])} [{_fmt_metric(c['task'], c['lo'])}, "
                         f"{_fmt_metric(c['task'], c['hi'])}], cost {c['cost']:.2f}{held})")
        elif c["verdict"] == "undecided":
            parts.append(f"**{c['requirement']}**: undecided: {c['decision']}")
        else:
            parts.append(f"**{c['requirement']}**: not met: {c['decision']}")
        note = answer_note(summary, c["requirement"])
        if note:
            parts[-1] += f"; {note.rstrip('.')}"
    model = summary.get("world_model")
    where = (f" Simulated world: sensor {model['sensor']}, scenes with {model['scene']}." if model else "")
    return "; ".join(parts) + "." + where


def _slug(req: str) -> str:
    return req.split()[0] + ("_" + req.split("[")[1].rstrip("]").replace("=", "_") if "[" in req else "")


def write_design_report(result: dict, out) -> dict:
    """Write ``report.md``, ``report.html`` and the PNGs into ``out``.

    Parameters
    ----------
    result : dict
        :func:`nlosplan.planner.design.run.run_design`'s result.
    out : str or Path

    Returns
    -------
    dict
        ``markdown``, ``html`` and ``plots`` (name -> path).
    """
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    plots = {}
    for req in result["requirements_asked"]:
        plots[f"trade-offs: {req}"] = plot_tradeoffs(result, req, out / f"tradeoffs_{_slug(req)}.png")
    plots["Pareto fronts"] = plot_pareto(result, out / "pareto.png")
    plots["evaluators: error against run time"] = plot_evaluators(result, out / "evaluators.png")
    curves = plot_learning_curves(result, out / "learning_curves.png")
    if curves is not None:
        plots["learning curves at DENALI's design"] = curves
    prov = result["provenance"]
    answer, reqs = answer_table(result), requirements_table(result)
    stab = result.get("stability") or {}
    stab_text = (f"{stab['passed']} of {stab['total']} cases passed in {stab['seconds']:.0f} s"
                 + (" (this code's result, kept from an earlier run)" if stab.get("cached") else "")
                 + (f"; FAILED: {', '.join(stab['failed'])}" if stab.get("failed") else "")
                 if stab.get("ran") else stab.get("note", "not run"))
    unreachable = result["unreachable"]
    failures = result["failures"]
    wsum = result.get("worlds")
    sections = [
        (DENALI_TITLE, denali_point_text(result), denali_point_table(result)),
        ("Answer: the cheapest design per task", _headline(result), answer),
        ("Minimum requirement per parameter",
         f"Along each parameter from the reference ({result['reference_sensor']}, the others kept), the least "
         "hardware whose trained model meets the requirement, interpolated between grid points; the interval comes "
         "from the metric's 95 % interval (met: its pessimistic end crosses within the range; undecided: only its "
         "optimistic end does). 'min' = at least, 'max' = at most.", reqs),
        ("Metrics and verdicts", _definitions_text(result)
         + f" Intervals: the mean over a design's runs (each a new seed: new Poisson noise, train/test split and "
           f"training seed) with the run-to-run spread pooled over the designs of the task; "
           f"{result['budget']['spent']} of {result['budget']['extra_evaluations']} extra evaluations spent deciding "
           f"(at most {result['budget']['max_seeds']} seeds per design).", pd.DataFrame()),
        ("Learners on the reference design",
         "Every candidate model trained on the reference design; the best of each task is the one every design "
         "of that task is trained with.", learners_table(result)),
    ]
    if wsum:
        sections += [
            ("Worlds: what would change this answer",
             f"The cheapest met candidates of each requirement in {wsum['count']} plausible worlds ("
             + "; ".join(wsum["sources"]) + f"); a design is the minimum hardware when met in at least "
             f"{wsum['needed']} of them ({100 * wsum['quorum']:.0f} %). Worlds simulate {wsum['scenes_per_world']} "
             f"scenes each (1 in {wsum['scene_step']} of the run's gantry positions): a world's metric is the verified value shifted by "
             f"the paired world effect, whose run-to-run variance is {wsum['variance_factor']:.1f}x a run's on the "
             "full scenes (the cost of fewer scenes in interval width)." + _worlds_budget_text(result),
             worlds_table(result)),
            ("The worlds drawn", "Each world's parameters (sensor fields and DENALI scene arguments).",
             world_parameters_table(result)),
        ]
    sections += [
        ("Bound-to-trained gap (multi-fidelity)",
         "How far the trained models are from the fast bounds on the designs evaluated by both; the optimizer "
         "screens with the bound corrected by this gap, and the cheapest candidates are verified by training.",
         _gap_rows(result)),
        (CONSISTENCY_TITLE, consistency_text(result), consistency_table(result)),
        ("Evaluators: error against run time", "Every evaluation records its run time and interval.",
         _evaluator_rows(result)),
    ]
    sections.insert(2, realism_section(result["reference_sensor"]))
    if result.get("disagreements"):
        n = sum(d["disagree"] for d in result["disagreements"])
        sections.append(("Simulated against real captures",
                         f"The same designs trained on real and on simulated captures; {n} of "
                         f"{len(result['disagreements'])} disagree (95 % intervals apart).", _disagreement_rows(result)))
    md = [f"# nlosplan design — minimum hardware per NLOS task ({result['provenance']['config']['label']} run)", ""]
    for title, text, df in sections:
        md += [f"## {title}", "", text, "", markdown_table(df) if len(df) else ("(none)" if len(df.columns) else ""),
               ""]
    md += ["## Plots", ""] + [f"![{k}]({Path(v).name})" for k, v in plots.items()] + [""]
    md += ["## Stability catalog (`nlosplan check`)", "", stab_text, ""]
    md += ["## Failed evaluations", "", f"{len(failures)} failed" + (":" if failures else "."), ""]
    md += [f"- {f['evaluator']} {f['task']} {f['design']}: {f['reason']}" for f in failures[:20]] + [""]
    md += ["## Unreachable designs", "", f"{len(unreachable)}" + (":" if unreachable else "."), ""]
    md += [f"- {u}" for u in unreachable[:20]] + [""]
    md += ["## Provenance", "", f"- wall time: {prov['wall_seconds']:.1f} s on {prov['cpus']} CPUs ({prov['executor']})",
           f"- git revision: {prov['git_revision']}; configuration hash {prov['config_hash']}; seed {prov['seed']} "
           f"({prov['seeds']})",
           "- versions: " + ", ".join(f"{k} {v}" for k, v in prov["versions"].items()),
           f"- references: {json.dumps(result['references'])}", "", "```json",
           json.dumps(prov["config"], indent=1), "```", ""]
    md_path = out / "report.md"
    write_text(md_path, "\n".join(md))
    html_path = out / "report.html"
    write_text(html_path, _html(result, sections, plots, stab_text, failures, unreachable, prov))
    return {"markdown": str(md_path), "html": str(html_path), "plots": {k: str(v) for k, v in plots.items()}}


_CSS = """body{font-family:system-ui,sans-serif;max-width:1180px;margin:24px auto;padding:0 16px;color:#222}
table{border-collapse:collapse;font-size:13px;margin:8px 0 18px}td,th{border:1px solid #ccc;padding:4px 8px;
text-align:left;vertical-align:top}th{background:#f2f2f2}.no{color:#b00;font-weight:bold}.yes{color:#070;
font-weight:bold}img{max-width:100%;border:1px solid #ddd;margin:6px 0}h1{font-size:22px}h2{font-size:18px;
margin-top:28px}.lead{font-size:15px;background:#f7f7fb;padding:10px 14px;border-left:4px solid #446}
pre{background:#f6f6f6;padding:8px;font-size:11px;overflow:auto}"""


def _df_html(df: pd.DataFrame) -> str:
    if not len(df):
        return "<p>(none)</p>" if len(df.columns) else ""
    head = "".join(f"<th>{html.escape(str(c))}</th>" for c in df.columns)
    body = []
    for row in df.itertuples(index=False):
        cells = []
        for v in row:
            s = html.escape(str(v))
            cls = ' class="no"' if s == "NO" else (' class="yes"' if s == "yes" else "")
            cells.append(f"<td{cls}>{s}</td>")
        body.append("<tr>" + "".join(cells) + "</tr>")
    return f"<table><tr>{head}</tr>{''.join(body)}</table>"


def _html(result, sections, plots, stab_text, failures, unreachable, prov) -> str:
    parts = [f"<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'><title>nlosplan design report</title>"
             f"<style>{_CSS}</style></head><body>",
             f"<h1>nlosplan design — minimum hardware per NLOS task ({html.escape(prov['config']['label'])} run)</h1>"]
    for i, (title, text, df) in enumerate(sections):
        parts.append(f"<h2>{html.escape(title)}</h2>")
        lead = html.escape(text).replace("**", "")
        parts.append(f"<p class='lead'>{lead}</p>" if i < 2 else f"<p>{lead}</p>")
        parts.append(_df_html(df))
    parts.append("<h2>Plots</h2>")
    for name, path in plots.items():
        data = base64.b64encode(Path(path).read_bytes()).decode()
        parts.append(f"<h3>{html.escape(name)}</h3><img alt='{html.escape(name)}' src='data:image/png;base64,{data}'>")
    parts.append(f"<h2>Stability catalog</h2><p>{html.escape(stab_text)}</p>")
    parts.append(f"<h2>Failed evaluations</h2><p>{len(failures)} failed</p><ul>"
                 + "".join(f"<li>{html.escape(f['evaluator'])} {html.escape(f['task'])} {html.escape(f['design'])}: "
                           f"{html.escape(f['reason'])}</li>" for f in failures[:20]) + "</ul>")
    parts.append(f"<h2>Unreachable designs</h2><p>{len(unreachable)}</p>")
    parts.append("<h2>Provenance</h2><ul>"
                 f"<li>wall time {prov['wall_seconds']:.1f} s on {prov['cpus']} CPUs ({html.escape(prov['executor'])})</li>"
                 f"<li>git revision {html.escape(prov['git_revision'])}, configuration {prov['config_hash']}, "
                 f"seed {prov['seed']} ({html.escape(prov['seeds'])})</li><li>versions: "
                 + html.escape(", ".join(f"{k} {v}" for k, v in prov["versions"].items())) + "</li></ul>"
                 f"<pre>{html.escape(json.dumps(prov['config'], indent=1))}</pre>")
    # for headless checks: how many images decoded (the report works without it)
    parts.append("<script>window.addEventListener('load',()=>{const i=[...document.images];"
                 "document.body.dataset.images=i.length;"
                 "document.body.dataset.imagesLoaded=i.filter(x=>x.complete&&x.naturalWidth>0).length;});</script>")
    parts.append("</body></html>")
    return "\n".join(parts)
