"""The design page: stage and progress, the answer so far, trade-off plots, the evaluators' error against run time.

Built per browser session on a :class:`~nlosplan.reports.live.design_watch.DesignWatch`
shared by every session; a periodic callback refreshes the watch and pushes
what changed to the browser (Bokeh server, websocket). Read-only: the page
offers no actions.
"""

from __future__ import annotations

import math

from nlosplan.reports.live.design_watch import DesignWatch, _design_key
from nlosplan.reports.live.html import STYLE, duration, esc, fmt, table

__all__ = ["build_design_document", "status_html", "answer_rows"]

#: x axes of the trade-off plots: label and how to read it from a logged design (a dict).
X_AXES = {
    "cost": "relative cost (0 = cheapest design of the space)",
    "zones": "zones (count)",
    "bin_factor": "bin width (× the reference's)",
    "n_bins": "bins",
    "jitter_fwhm_ps": "jitter FWHM (ps)",
    "pulse_fwhm_ps": "pulse FWHM (ps)",
    "photon_fraction": "photons (fraction of the reference's)",
}
EVALUATOR_COLORS = {"bound": "#1f77b4", "trained": "#d62728", "trained_sim": "#2ca02c",
                    "learning_curve": "#9467bd"}
TASK_MARKERS = {"loc": "circle", "shape": "square", "size": "triangle"}


def _x_of(design: dict, axis: str, cost: float | None):
    if axis == "cost":
        return cost
    v = design.get(axis) if isinstance(design, dict) else None
    if axis == "zones":
        if isinstance(v, str) and "x" in v:
            r, c = v.lower().split("x")
            return float(int(r) * int(c))
        if isinstance(v, (list, tuple)) and len(v) == 2:
            return float(v[0] * v[1])
    return float(v) if isinstance(v, (int, float)) else None


def status_html(watch: DesignWatch) -> str:
    """The status block: folder, stage, evaluations done / left, time left, failures (every value from the
    run's files or a flag escaped)."""
    from nlosplan.planner.design.progress import STAGES

    p = watch.progress
    label = f"(<span data-k='label'>{esc(watch.label)}</span>)" if watch.label else ""
    lines = [f"<b>design run</b> <span data-k='folder'>{esc(watch.out)}</span> {label}"]
    if p is None:
        lines.append(f"<span class='nl-warn'>progress unknown: <span data-k='progress_error'>"
                     f"{esc(watch.progress_error)}</span></span>")
        lines.append(f"evaluations logged: <span data-k='done'>{len(watch.results)}</span>")
    else:
        stages = " → ".join(f"<b data-k='stage'>{esc(s)}</b>" if s == p["stage"] else esc(s) for s in STAGES)
        lines.append(f"stage: {stages}")
        left = ", ".join(f"{esc(k)} {esc(v)}" for k, v in sorted(p["left_by_evaluator"].items()))
        lines.append(f"evaluations done <b data-k='done'>{esc(p['done'])}</b> · left in this stage "
                     f"<b data-k='left'>{esc(p['left'])}</b>{' (' + left + ')' if left else ''} · planned so far "
                     f"<b data-k='planned'>{esc(p['done'] + p['left'])}</b> (later stages are planned when they "
                     "start)")
        secs = watch.seconds_left()
        eta = duration(secs) if secs is not None else ("—" if not p["left"] else "estimating (needs evaluations "
                                                                                 "landing while the page watches)")
        lines.append(f"time left in this stage: <b data-k='eta'>{eta}</b>")
        failed = p["failed"]
        lines.append(f"failed evaluations: <b data-k='failed' class='{'nl-warn' if failed else 'nl-ok'}'>"
                     f"{esc(failed)}</b>")
    since = watch.seconds_since_last()
    state = "finished (result.json written)" if watch.result is not None and watch.answer() is watch.result \
        else f"running or stopped; last evaluation {duration(since)} ago" if since is not None else "no evaluation yet"
    lines.append(f"state: <span data-k='state'>{state}</span>")
    return STYLE + "<div class='nl-status'>" + "<br>".join(lines) + "</div>"


def answer_rows(answer: dict | None) -> tuple[list[dict], list[dict]]:
    """(cheapest design per requirement, minimum requirement per parameter) rows as the page shows them.

    The rows are the answer's own (``result.json`` or the answer so far), with whatever fields they
    carry; the cheapest rows get a ``metric [interval]`` column from ``value``, ``lo``, ``hi``, and a
    nested ``design`` is shown by its ``key``.
    """
    if not answer:
        return [], []
    cheapest = []
    for r in answer.get("cheapest") or []:
        row = {k: v for k, v in r.items() if not (k == "design" and "key" in r)}
        if "value" in r:
            v, lo, hi = r.get("value"), r.get("lo"), r.get("hi")
            row["metric [interval]"] = "—" if v is None else (f"{fmt(v)} [{fmt(lo)}, {fmt(hi)}]"
                                                              if lo is not None and hi is not None else fmt(v))
        cheapest.append(row)
    return cheapest, list(answer.get("requirements") or [])


def build_design_document(doc, watch: DesignWatch, *, poll_ms: int = 1000) -> None:
    """Fill a Bokeh document with the design page (``doc`` of a server session)."""
    from bokeh.layouts import column, row
    from bokeh.models import ColumnDataSource, Div, HoverTool, Select, Span, Whisker
    from bokeh.plotting import figure

    watch.refresh(force=True)
    head = Div(text="<h2 style='font:600 18px sans-serif;margin:4px 0'>nlosplan · design run</h2>")
    status = Div(text="", name="status")
    cheapest_div = Div(text="", name="answer")
    params_div = Div(text="", name="parameters")
    axis = Select(title="trade-off plots: x axis", value="cost", options=[(k, v) for k, v in X_AXES.items()],
                  name="x_axis", width=320)
    figs, sources = [], []
    plots = column(name="tradeoffs")

    def make_trade() -> None:
        figs.clear()
        sources.clear()
        for req in watch.groups():
            src = ColumnDataSource(dict(x=[], value=[], lo=[], hi=[], evaluator=[], color=[], design=[], seed=[],
                                        seconds=[], cost=[], status=[]), name=f"tradedata:{req['name']}")
            f = figure(width=430, height=320, title=req["name"], x_axis_label=X_AXES[axis.value],
                       y_axis_label=req["metric"], tools="pan,wheel_zoom,box_zoom,reset,save",
                       name=f"trade:{req['name']}")
            f.add_layout(Whisker(source=src, base="x", lower="lo", upper="hi", line_color="color", line_alpha=0.6))
            r = f.scatter("x", "value", source=src, color="color", size=8, alpha=0.8, legend_field="evaluator")
            f.scatter("x", "lo", source=src, alpha=0)   # the intervals inside the auto range
            f.scatter("x", "hi", source=src, alpha=0)
            f.add_tools(HoverTool(renderers=[r], tooltips=[
                ("design", "@design"), ("evaluator", "@evaluator (seed @seed)"),
                ("value", "@value{0.0000} [@lo{0.0000}, @hi{0.0000}]"), ("cost", "@cost{0.000}"),
                ("run time", "@seconds{0.00} s"), ("status", "@status")]))
            if req["threshold"] is not None:
                f.add_layout(Span(location=req["threshold"], dimension="width", line_dash="dashed",
                                  line_color="black"))
            f.legend.label_text_font_size = "9pt"
            f.legend.orientation = "horizontal"
            f.add_layout(f.legend[0], "below")
            figs.append(f)
            sources.append((req, src))
        plots.children = [row(*figs[i:i + 3]) for i in range(0, len(figs), 3)]

    err_src = ColumnDataSource(dict(seconds=[], half=[], label=[], color=[], marker=[], design=[], value=[]),
                               name="errors")
    ef = figure(width=560, height=320, title="evaluators: interval half-width against run time", x_axis_type="log",
                y_axis_type="log", x_axis_label="run time (s)", y_axis_label="half-width (metric units)",
                tools="pan,wheel_zoom,box_zoom,reset,save", name="errors")
    er = ef.scatter("seconds", "half", source=err_src, color="color", marker="marker", size=7, alpha=0.7,
                    legend_field="label")
    ef.add_tools(HoverTool(renderers=[er], tooltips=[("", "@label"), ("design", "@design"),
                                                     ("run time", "@seconds{0.000} s"), ("half-width", "@half{0.0000}"),
                                                     ("value", "@value{0.0000}")]))
    ef.legend.label_text_font_size = "8pt"
    ef.add_layout(ef.legend[0], "right")
    seen = {"version": -1}

    def costs() -> dict:
        return (watch.progress or {}).get("costs") or {}

    def fill_trade():
        c = costs()
        for req, src in sources:
            data = {k: [] for k in src.data}
            for r in watch.results:
                if r.get("task") != req["task"] or r.get("condition") != req["condition"]:
                    continue
                v = r.get("value")
                if r.get("status") != "ok" or not isinstance(v, (int, float)) or not math.isfinite(v):
                    continue
                key = _design_key(r.get("design"))
                x = _x_of(r.get("design"), axis.value, c.get(key))
                if x is None:
                    continue
                lo, hi = r.get("lo"), r.get("hi")
                data["x"].append(x)
                data["value"].append(v)
                data["lo"].append(lo if isinstance(lo, (int, float)) and math.isfinite(lo) else v)
                data["hi"].append(hi if isinstance(hi, (int, float)) and math.isfinite(hi) else v)
                data["evaluator"].append(str(r.get("evaluator")))
                data["color"].append(EVALUATOR_COLORS.get(r.get("evaluator"), "#777"))
                data["design"].append(key)
                data["seed"].append(r.get("seed"))
                data["seconds"].append(r.get("seconds"))
                data["cost"].append(c.get(key))
                data["status"].append(r.get("status"))
            src.data = data
        for f in figs:
            f.xaxis.axis_label = X_AXES[axis.value]

    def fill():
        if [g["name"] for g in watch.groups()] != [r["name"] for r, _ in sources]:
            make_trade()
        status.text = status_html(watch)
        cheapest, params = answer_rows(watch.answer())
        final = watch.result is not None and watch.answer() is watch.result
        which = "result.json" if final else "the answer so far (from the evaluations logged)"
        cheapest_div.text = (STYLE + f"<b>cheapest design per requirement</b> — {which}"
                             + table(cheapest, name="cheapest"))
        params_div.text = (STYLE + "<b>minimum requirement per parameter</b>"
                           + table(params, name="parameters", drop=("points", "screened_out")))
        fill_trade()
        data = {k: [] for k in err_src.data}
        for e in watch.evaluators():
            if e["half"] is None or e["half"] <= 0 or not e["seconds"]:
                continue
            data["seconds"].append(e["seconds"])
            data["half"].append(e["half"])
            data["label"].append(f"{e['evaluator']} {e['task']}")
            data["color"].append(EVALUATOR_COLORS.get(e["evaluator"], "#777"))
            data["marker"].append(TASK_MARKERS.get(e["task"], "diamond"))
            data["design"].append(e["design"])
            data["value"].append(e["value"])
        err_src.data = data

    def update():
        watch.refresh()
        if watch.version != seen["version"]:
            seen["version"] = watch.version
            fill()
        else:
            status.text = status_html(watch)  # the clock and the time left move on

    axis.on_change("value", lambda attr, old, new: fill_trade())
    fill()
    seen["version"] = watch.version
    doc.add_periodic_callback(update, poll_ms)
    doc.add_root(column(head, status, cheapest_div, params_div, axis, plots, ef, name="design_page"))
    doc.title = f"nlosplan design · {watch.out.name}"
