"""The rig page's approval panel: approve, edit (drop or add positions on the map) or refuse the proposed batch.

The answer goes to the run through the approval files
(:mod:`nlosplan.planner.capture.approval`); the first answer wins, the run's
terminal prompt or this page. The panel acts only in a session that is
allowed to (the server checks the token of its URL); any other session
shows the batch read-only. The run checks an edited batch again
(:meth:`~nlosplan.planner.capture.planner.CapturePlanner.amend`) and asks
again if it cannot be run.
"""

from __future__ import annotations

import math

import numpy as np

from nlosplan.errors import UserError
from nlosplan.planner.capture.approval import Answer, submit_answer
from nlosplan.reports.live.html import STYLE, esc, table

__all__ = ["ApprovalPanel", "snap_radius_mm"]


def snap_radius_mm(points_mm) -> float:
    """How far from a candidate a click still picks it: half the smallest spacing (at least 3 mm)."""
    p = np.asarray(points_mm, dtype=float).reshape(-1, 2)
    if len(p) < 2:
        return 10.0
    d = np.sqrt(((p[:, None, :] - p[None, :, :]) ** 2).sum(-1))
    d[d == 0] = np.inf
    return max(3.0, 0.5 * float(d.min()))


class ApprovalPanel:
    """Buttons, the batch table and map edits of one browser session.

    Parameters
    ----------
    doc : bokeh Document
    watch : RigWatch
    map_fig : bokeh figure
        The rig map (taps on it edit the batch).
    allowed : callable
        ``allowed() -> (bool, why_not)``: whether this session may answer now (token checked,
        actions enabled, store writable), and what to show when not.
    """

    def __init__(self, doc, watch, map_fig, *, allowed):
        from bokeh.events import Tap
        from bokeh.layouts import column, row
        from bokeh.models import Button, ColumnDataSource, Div

        self.watch, self._allowed = watch, allowed
        self.allowed, self.why_not = allowed()
        self.request_id: str | None = None
        self.drop: set[str] = set()
        self.add: list[int] = []
        self.message = ""
        self.sent: str | None = None
        self.status = Div(text="", name="approval")
        self.batch = Div(text="", name="batch")
        self.approve_btn = Button(label="Approve batch", button_type="success", name="approve", width=150)
        self.refuse_btn = Button(label="Refuse batch (end the run)", button_type="danger", name="refuse", width=190)
        self.reset_btn = Button(label="Undo edits", name="undo", width=100)
        self.edits = ColumnDataSource({"x": [], "y": [], "kind": [], "color": []}, name="map:edits")
        map_fig.scatter("x", "y", source=self.edits, size=16, fill_alpha=0, line_width=3, color="color",
                        legend_label="edits (dropped red, added green)")
        self.approve_btn.on_click(self._approve)
        self.refuse_btn.on_click(self._refuse)
        self.reset_btn.on_click(self._reset)
        map_fig.on_event(Tap, self._tap)
        self.layout = column(self.status, self.batch, row(self.approve_btn, self.refuse_btn, self.reset_btn),
                             name="approval_panel")

    # ------------------------------------------------------------------ state
    def _request(self):
        return self.watch.awaiting()

    def _candidates(self) -> tuple[np.ndarray, list[str]]:
        from nlosplan.reports.live.rig_page import _map_data

        c = _map_data(self.watch)["cand"]
        return np.column_stack([c["x"], c["y"]]) if c["x"] else np.zeros((0, 2)), c["state"]

    def fill(self) -> None:
        self.allowed, self.why_not = self._allowed()
        req = self._request()
        rid = None if req is None else req["request_id"]
        if rid != self.request_id:
            self.request_id, self.drop, self.add, self.sent = rid, set(), [], None
            self.message = ""
        pend = self.watch.pending()
        if req is None:
            last = self.watch.approval
            done = ("" if not last else f"batch {esc(last.get('batch'))} was answered: <b data-k='decision'>"
                    f"{esc(last.get('decision'))}</b> by <span data-k='answered_by'>{esc(last.get('answered_by'))}"
                    "</span>" + (f" (<span data-k='note'>{esc(last.get('note'))}</span>)" if last.get("note") else ""))
            self.status.text = STYLE + f"<div class='nl-status'>no batch awaits approval. {done}</div>"
        else:
            who = "" if self.allowed else f"<br><span class='nl-warn'>read-only: {esc(self.why_not)}</span>"
            sent = f"<br><b class='nl-ok'>sent: {esc(self.sent)}</b> — waiting for the run" if self.sent else ""
            msg = f"<br><span class='nl-warn'>{esc(self.message)}</span>" if self.message else ""
            self.status.text = (STYLE + f"<div class='nl-status'><b data-k='awaiting'>batch {esc(req['batch'])} "
                                f"awaits approval</b> ({len(req['ids'])} positions; budget leaves "
                                f"{esc(req.get('budget_left', '?'))} more). Click a proposed position on the map to drop "
                                f"it, a free candidate to add it.{who}{sent}{msg}</div>")
        rows = [{"#": k + 1, "id": p["id"], "x_mm": round(p["x_mm"], 1), "y_mm": round(p["y_mm"], 1),
                 "edit": "drop" if p["id"] in self.drop else ""} for k, p in enumerate(pend)]
        pts, _ = self._candidates()
        rows += [{"#": "+", "id": f"candidate {i}", "x_mm": round(float(pts[i, 0]), 1),
                  "y_mm": round(float(pts[i, 1]), 1), "edit": "add"} for i in self.add if i < len(pts)]
        self.batch.text = STYLE + table(rows, name="batch")
        self._draw_edits(pend, pts)
        live = req is not None and self.allowed and self.sent is None
        self.approve_btn.disabled = self.refuse_btn.disabled = self.reset_btn.disabled = not live

    def _draw_edits(self, pend, pts) -> None:
        xs, ys, kind, color = [], [], [], []
        for p in pend:
            if p["id"] in self.drop:
                xs.append(p["x_mm"]), ys.append(p["y_mm"]), kind.append("drop"), color.append("#d62728")
        for i in self.add:
            if i < len(pts):
                xs.append(float(pts[i, 0])), ys.append(float(pts[i, 1])), kind.append("add"), color.append("#2ca02c")
        self.edits.data = {"x": xs, "y": ys, "kind": kind, "color": color}

    # ------------------------------------------------------------------ actions
    def _tap(self, event) -> None:
        req = self._request()
        if req is None or not self.allowed or self.sent is not None:
            return
        pts, state = self._candidates()
        if not len(pts):
            return
        d = np.hypot(pts[:, 0] - event.x, pts[:, 1] - event.y)
        i = int(np.argmin(d))
        if not math.isfinite(d[i]) or d[i] > snap_radius_mm(pts):
            self.message = f"no candidate near ({event.x:.0f}, {event.y:.0f}) mm"
        else:
            self.message = self.toggle(i, state[i])
        self.fill()

    def toggle(self, index: int, state: str) -> str:
        """Drop or restore a proposed position, add or remove a free candidate; returns a message."""
        prop = next((p for p in self.watch.pending() if int(p["index"]) == index), None)
        if prop is not None:
            self.drop ^= {prop["id"]}
            return ""
        if index in self.add:
            self.add.remove(index)
            return ""
        if state != "free":
            return f"candidate {index} is {state}: it cannot be added"
        req = self._request() or {}
        room = req.get("budget_left")
        if room is not None and len(self.add) + 1 > int(room) + len(self.drop):
            return f"the budget leaves room for {int(room) + len(self.drop)} added position(s)"
        self.add.append(index)
        return ""

    def _send(self, answer: Answer) -> None:
        if self._request() is None or not self.allowed:
            return
        try:
            ok = submit_answer(self.watch.planner_dir, self.request_id, answer)
        except UserError as exc:
            self.message = str(exc)
            self.fill()
            return
        label = answer.decision + (" (edited)" if answer.edited else "")
        self.sent = label if ok else None
        self.message = "" if ok else "already answered (by the terminal or another page)"
        self.fill()

    def _approve(self) -> None:
        pend = [p["id"] for p in self.watch.pending()]
        if self.drop >= set(pend) and not self.add:
            self.message = "every position is dropped: refuse the batch instead"
            self.fill()
            return
        self._send(Answer("approve", tuple(sorted(self.drop)), tuple(self.add), by="page"))

    def _refuse(self) -> None:
        self._send(Answer("refuse", by="page"))

    def _reset(self) -> None:
        self.drop, self.add, self.message = set(), [], ""
        self.fill()
