"""The rig page: rig map, last histogram of every zone, captures and faults, the planner's RMSE and calibration.

Built per browser session on a :class:`~nlosplan.reports.live.rig_watch.RigWatch`
shared by every session. With a ``rig run --approve`` folder and a session
allowed to act (:mod:`nlosplan.reports.live.rig_approval`), the proposed batch
can be approved, edited on the map or refused.
"""

from __future__ import annotations

import math

import numpy as np

from nlosplan.reports.live.html import STYLE, duration, esc, fmt, table
from nlosplan.reports.live.rig_watch import IDLE_AFTER_S, RigWatch

__all__ = ["build_rig_document", "status_html"]

CALIBRATION = (("dx_m", 1e3, "dx (mm)"), ("dy_m", 1e3, "dy (mm)"), ("log_photon_scale", 100.0, "photon scale (log, %)"),
               ("log_albedo", 100.0, "albedo (log, %)"))
MAX_LINE_ZONES = 16


def status_html(watch: RigWatch) -> str:
    """The status block: store, run, captures stored / planned / left, faults, state (every value from the
    store, the run folder or a flag escaped)."""
    run = watch.run_id
    lines = [f"<b>capture store</b> {esc(watch.store)}" + ("" if watch.writable or not watch.opened else
                                                       " <span class='nl-warn'>(read-only: archived)</span>")]
    if not watch.opened:
        lines.append("waiting for the run to create the store")
        return STYLE + "<div class='nl-status'>" + "<br>".join(lines) + "</div>"
    if run is None:
        lines.append(f"no rig run in this store yet ({esc(watch.total)} captures of other sources)")
        return STYLE + "<div class='nl-status'>" + "<br>".join(lines) + "</div>"
    if not watch.runs.get(run):
        lines.append(f"<b>run</b> <span data-k='run'>{esc(run)}</span>: no capture yet")
        if watch.awaiting():
            lines.append("state: <b data-k='state'>awaiting approval</b>")
        return STYLE + "<div class='nl-status'>" + "<br>".join(lines) + "</div>"
    m, c, f = watch.meta(), watch.counts(), watch.faults()
    lines.append(f"<b>run</b> <span data-k='run'>{esc(run)}</span> · {esc(m.get('object'))} {esc(m.get('size'))}, "
                 f"{esc(m.get('zones'))} zones, lights {esc(m.get('lights'))}, {esc(m.get('source'))} · plan: "
                 f"{esc(m.get('plan', '?'))}")
    planned = "?" if c["planned"] is None else esc(c["planned"])
    left = "?" if c["left"] is None else esc(c["left"])
    unit = esc(c["planned_unit"])
    lines.append(f"captures stored <b data-k='captures'>{esc(c['captures'])}</b> at <b data-k='positions'>"
                 f"{esc(c['positions'])}"
                 f"</b> positions · planned <b data-k='planned'>{planned}</b> {unit} · left <b data-k='left'>{left}</b> "
                 f"{unit}")
    lines.append("faults: " + " · ".join(
        f"{label} <b data-k='{k}' class='{'nl-warn' if f[k] else 'nl-ok'}'>{esc(fmt(f[k]))}</b>"
        for k, label in (("dropped_frames", "dropped frames"), ("dropped_dumps", "dropped dumps"),
                         ("garbage_lines", "garbage lines"), ("retries", "frame retries"),
                         ("reconnects", "sensor reconnects"), ("failed_captures", "failed positions"))))
    for fail in f["failures"][-3:]:
        lines.append(f"<span class='nl-warn'>failed {esc(fail.get('id'))}: {esc(fail.get('reason'))}</span>")
    since = watch.seconds_since_last()
    pos = watch.current_position()
    lines.append(f"gantry last reported at <b data-k='position'>"
                 f"{'—' if pos is None else f'({pos[0]:.1f}, {pos[1]:.1f}) mm'}</b> · last capture "
                 f"{duration(since)} ago")
    planner = watch.planner or {}
    state = ("awaiting approval" if watch.awaiting() else f"finished: {esc(planner['finished'])}"
             if planner.get("finished") else "idle or ended" if since is not None and since > IDLE_AFTER_S else "running")
    lines.append(f"state: <b data-k='state'>{state}</b>")
    return STYLE + "<div class='nl-status'>" + "<br>".join(lines) + "</div>"


def _map_data(watch: RigWatch) -> dict:
    """Columns of the map's sources: candidates, keep-out, captured, current position, route."""
    planner = watch.planner or {}
    space = planner.get("space") or {}
    pts = np.asarray(space.get("points_mm") or np.zeros((0, 2)), dtype=float).reshape(-1, 2)
    obs = {int(o["index"]) for o in planner.get("observations") or []}
    pend = {int(p["index"]) for p in watch.pending()}
    fails = {}
    for fl in planner.get("failures") or []:
        fails[int(fl["index"])] = fails.get(int(fl["index"]), 0) + 1
    state = ["captured" if i in obs else "proposed" if i in pend else "given up" if fails.get(i, 0) >= 2 else "free"
             for i in range(len(pts))]
    excl = space.get("excluded") or []
    cap = watch.captured_positions()
    here = watch.current_position()
    if here is None and planner.get("position_mm"):
        here = tuple(planner["position_mm"])
    route = watch.pending()
    start = here if here is not None else tuple(planner.get("position_mm") or (math.nan, math.nan))
    return {
        "cand": {"x": pts[:, 0].tolist(), "y": pts[:, 1].tolist(), "index": list(range(len(pts))), "state": state},
        "keepout": {"x": [e["x_mm"] for e in excl], "y": [e["y_mm"] for e in excl], "reason": [e["reason"] for e in excl]},
        "captured": {"x": [p["x_mm"] for p in cap], "y": [p["y_mm"] for p in cap], "captures": [p["captures"] for p in cap],
                     "step": [p["step"] for p in cap]},
        "here": {"x": [] if here is None else [here[0]], "y": [] if here is None else [here[1]]},
        "route": {"x": [start[0]] + [p["x_mm"] for p in route] if route else [],
                  "y": [start[1]] + [p["y_mm"] for p in route] if route else []},
        "proposed": {"x": [p["x_mm"] for p in route], "y": [p["y_mm"] for p in route], "id": [p["id"] for p in route],
                     "order": [str(k + 1) for k in range(len(route))], "index": [int(p["index"]) for p in route]},
    }


def _hist_data(watch: RigWatch) -> tuple[dict, dict, str]:
    h = watch.last_hist
    if h is None:
        return {"xs": [], "ys": [], "zone": [], "color": []}, {"image": [], "dw": [], "dh": []}, "no capture yet"
    counts = h["counts"]
    rows, cols, bins = counts.shape
    flat = counts.reshape(rows * cols, bins)
    x = list(range(bins))
    palette = ["#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f", "#bcbd22",
               "#17becf"]
    lines = {"xs": [x] * len(flat), "ys": [(v + 1.0).tolist() for v in flat],
             "zone": [f"{i // cols},{i % cols}" for i in range(len(flat))],
             "color": [palette[i % len(palette)] for i in range(len(flat))]}
    image = {"image": [np.log10(flat + 1.0)], "dw": [bins], "dh": [rows * cols]}
    return lines, image, f"last capture {h['capture_id']} (id {h['id']}): {rows}x{cols} zones, {bins} bins"


def _history_data(watch: RigWatch) -> tuple[dict, dict, float | None]:
    loop = (watch.planner or {}).get("loop") or {}
    hist = loop.get("history") or []
    rmse = {"captures": [], "rmse_mm": []}
    cal = {"captures": []}
    for _, _, label in CALIBRATION:
        cal[label], cal[label + " lo"], cal[label + " hi"] = [], [], []
    for r in hist:
        if r.get("cv_rmse_m") is not None and math.isfinite(r["cv_rmse_m"]):
            rmse["captures"].append(r["captures"])
            rmse["rmse_mm"].append(1e3 * r["cv_rmse_m"])
        th, sd = r.get("calibration_theta") or [], r.get("calibration_std") or []
        if len(th) == len(CALIBRATION):
            cal["captures"].append(r["captures"])
            for (_, scale, label), t, s in zip(CALIBRATION, th, sd or [0.0] * len(th)):
                cal[label].append(scale * t)
                cal[label + " lo"].append(scale * (t - s))
                cal[label + " hi"].append(scale * (t + s))
    target = loop.get("target_rmse_m")
    return rmse, cal, None if target is None else 1e3 * target


def build_rig_document(doc, watch: RigWatch, *, approval=None, poll_ms: int = 1000) -> None:
    """Fill a Bokeh document with the rig page.

    ``approval(doc, watch, map_figure)`` makes the session's
    :class:`~nlosplan.reports.live.rig_approval.ApprovalPanel` (None: a page without approval).
    """
    from bokeh.layouts import column, row
    from bokeh.models import ColumnDataSource, Div, HoverTool, LabelSet, LinearColorMapper, Span, Whisker
    from bokeh.plotting import figure

    watch.refresh(force=True)
    head = Div(text="<h2 style='font:600 18px sans-serif;margin:4px 0'>nlosplan · rig</h2>")
    status = Div(text="", name="status")
    d = _map_data(watch)
    src = {k: ColumnDataSource(v, name=f"map:{k}") for k, v in d.items()}
    lim = watch.limits_mm() or ((0.0, 320.0), (0.0, 320.0))
    pad = 0.06 * max(lim[0][1] - lim[0][0], lim[1][1] - lim[1][0])
    m = figure(width=520, height=520, title="rig map (gantry mm)", match_aspect=True, name="map",
               x_range=(lim[0][0] - pad, lim[0][1] + pad), y_range=(lim[1][0] - pad, lim[1][1] + pad),
               x_axis_label="gantry x (mm)", y_axis_label="gantry y (mm)", tools="pan,wheel_zoom,reset,save")
    box = ColumnDataSource({"left": [lim[0][0]], "right": [lim[0][1]], "bottom": [lim[1][0]], "top": [lim[1][1]]},
                           name="map:limits")
    m.quad(left="left", right="right", bottom="bottom", top="top", source=box, fill_alpha=0, line_dash="dashed",
           line_color="black", legend_label="gantry limits")
    rc = m.scatter("x", "y", source=src["cand"], size=7, color="#bbbbbb", legend_label="candidates")
    rk = m.scatter("x", "y", source=src["keepout"], marker="x", size=10, color="#cc3333", line_width=2,
                   legend_label="keep-out")
    rcap = m.scatter("x", "y", source=src["captured"], size=10, color="#1f77b4", legend_label="captured")
    m.line("x", "y", source=src["route"], color="#d62728", line_width=1.5)
    rp = m.scatter("x", "y", source=src["proposed"], size=12, color="#d62728", legend_label="next batch (route)")
    m.add_layout(LabelSet(x="x", y="y", text="order", source=src["proposed"], x_offset=6, y_offset=4,
                          text_font_size="9pt"))
    m.scatter("x", "y", source=src["here"], marker="square", size=13, color="black", legend_label="gantry now")
    m.add_tools(HoverTool(renderers=[rc], tooltips=[("candidate", "@index: (@x{0.0}, @y{0.0}) mm, @state")]))
    m.add_tools(HoverTool(renderers=[rk], tooltips=[("keep-out", "(@x{0.0}, @y{0.0}) mm"), ("why", "@reason")]))
    m.add_tools(HoverTool(renderers=[rcap], tooltips=[("captured", "(@x{0.0}, @y{0.0}) mm, @captures captures, "
                                                                   "from step @step")]))
    m.add_tools(HoverTool(renderers=[rp], tooltips=[("next", "#@order @id (@x{0.0}, @y{0.0}) mm")]))
    m.legend.label_text_font_size = "8pt"
    m.add_layout(m.legend[0], "below")
    m.legend.orientation = "horizontal"
    m.legend.ncols = 4
    lines, image, htitle = _hist_data(watch)
    hl = ColumnDataSource(lines, name="hist:lines")
    hi = ColumnDataSource(image, name="hist:image")
    hf = figure(width=520, height=300, title=htitle, y_axis_type="log", x_axis_label="bin",
                y_axis_label="counts + 1 (log)", tools="pan,wheel_zoom,box_zoom,reset,save", name="hist")
    hr = hf.multi_line("xs", "ys", source=hl, color="color", line_width=1)
    hf.add_tools(HoverTool(renderers=[hr], tooltips=[("zone", "@zone")]))
    imf = figure(width=520, height=300, title="log10(counts + 1) per zone and bin", x_axis_label="bin",
                 y_axis_label="zone (row-major)", tools="pan,wheel_zoom,reset,save", name="hist_image")
    imf.image("image", x=0, y=0, dw="dw", dh="dh", source=hi,
              color_mapper=LinearColorMapper(palette="Viridis256"))
    rmse, cal, target = _history_data(watch)
    rs = ColumnDataSource(rmse, name="rmse")
    cs = ColumnDataSource(cal, name="calibration")
    rf = figure(width=420, height=260, title="planner: cross-validated localization RMSE", x_axis_label="positions",
                y_axis_label="RMSE (mm)", tools="pan,wheel_zoom,reset,save", name="rmse")
    rf.line("captures", "rmse_mm", source=rs)
    rf.scatter("captures", "rmse_mm", source=rs, size=6)
    if target is not None:
        rf.add_layout(Span(location=target, dimension="width", line_dash="dashed"))
    cfigs = []
    for labels, title in ((("dx (mm)", "dy (mm)"), "calibration: registration offset (± 1 std)"),
                          (("photon scale (log, %)", "albedo (log, %)"), "calibration: photon scale, albedo (± 1 std)")):
        cf = figure(width=420, height=260, title=title, x_axis_label="positions", tools="pan,wheel_zoom,reset,save")
        for label, color in zip(labels, ("#1f77b4", "#d62728")):
            cf.line("captures", label, source=cs, color=color, legend_label=label)
            cf.scatter("captures", label, source=cs, color=color, size=5)
            cf.add_layout(Whisker(source=cs, base="captures", lower=label + " lo", upper=label + " hi",
                                  line_color=color))
            cf.scatter("captures", label + " lo", source=cs, alpha=0)   # the whiskers inside the auto range
            cf.scatter("captures", label + " hi", source=cs, alpha=0)
        cf.legend.label_text_font_size = "8pt"
        cfigs.append(cf)
    panel = approval(doc, watch, m) if approval is not None else None
    seen = {"version": -1}

    def fill():
        status.text = status_html(watch)
        now = watch.limits_mm()
        if now is not None and now != (tuple(box.data["left"] + box.data["right"]), tuple(box.data["bottom"]
                                                                                         + box.data["top"])):
            box.data = {"left": [now[0][0]], "right": [now[0][1]], "bottom": [now[1][0]], "top": [now[1][1]]}
            p = 0.06 * max(now[0][1] - now[0][0], now[1][1] - now[1][0])
            m.x_range.start, m.x_range.end = now[0][0] - p, now[0][1] + p
            m.y_range.start, m.y_range.end = now[1][0] - p, now[1][1] + p
        for k, v in _map_data(watch).items():
            if k in src and src[k].data != v:
                src[k].data = v
        lines, image, htitle = _hist_data(watch)
        hl.data, hi.data = lines, image
        hf.title.text = htitle
        many = len(lines["zone"]) > MAX_LINE_ZONES
        hf.visible, imf.visible = not many, many
        rmse, cal, _ = _history_data(watch)
        rs.data, cs.data = rmse, cal
        if panel is not None:
            panel.fill()

    def update():
        watch.refresh()
        if watch.version != seen["version"]:
            seen["version"] = watch.version
            fill()
        else:
            status.text = status_html(watch)

    fill()
    seen["version"] = watch.version
    doc.add_periodic_callback(update, poll_ms)
    runs = Div(text="", name="store")
    if watch.run_id is None:
        runs.text = STYLE + table(watch.summary(), name="store")
    right = [hf, imf, row(rf), row(*cfigs)]
    left = [m] + ([panel.layout] if panel is not None else [])
    doc.add_root(column(head, status, row(column(*left), column(*right)), runs, name="rig_page"))
    doc.title = f"nlosplan rig · {watch.run_id or watch.store.name}"

