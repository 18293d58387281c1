"""The live view against hostile files and local clients (no browser; the browser test is test_live_browser.py).

- Every Div of the rig page (approval panel included) and of the design page, built over a store, a run folder
  and a design folder whose every free-text field is hostile (run id, object, source, failure reasons, keep-out
  reasons, proposal ids, who answered and the note, the folder names, the design label, the error a broken
  checkpoint gives, result.json's rows): parsed as HTML, no element or attribute the page did not write itself,
  and the hostile text is there, literally, as text.
- The log filter: the token redacted (query argument, literal, in arguments and exceptions), one line a record,
  control characters escaped, a rate limit; a real server's 500 on ``/?token=...`` logged redacted.
- Sessions dropped when unused and capped; ``serve``'s token from a file or stdin (never argv), ``--poll`` and
  ``--allow-origin`` checked before any work; malformed websocket messages and a refused origin give one line
  each, no traceback; SIGTERM and SIGINT stop ``serve`` with 143 and 130.
"""

import asyncio
import io
import json
import logging
import os
import re
import signal
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest

from nlosplan.cli import main
from nlosplan.data.store import CaptureStore
from nlosplan.planner.capture.approval import Answer, close_request, post_request
from nlosplan.reports.live import server as live_server
from nlosplan.reports.live.html import esc
from nlosplan.reports.live.logs import REDACTED, Redact, redact, server_logs
from nlosplan.reports.live.server import Page, bind, parse_origin, serve, websocket_origins
from nlosplan.sensor_models import preset

ROOT = Path(__file__).resolve().parents[1]
ENV = {**os.environ, "PYTHONPATH": str(ROOT)}
IMG = "<img src=x onerror=alert(1)>"                      # no '/': it can be a folder's name too
QUOTE = "\"'><svg onload=alert(2)>"                        # breaks out of a quoted attribute
SCRIPT = "</span></div><script>alert(3)</script>"
PAGE_TAGS = {"style", "div", "b", "span", "br", "table", "thead", "tbody", "tr", "th", "td", "h2", "p"}
PAGE_ATTRS = {"class", "data-k", "data-col", "data-name", "title", "style"}


class Parsed(HTMLParser):
    def __init__(self, text):
        super().__init__(convert_charrefs=True)
        self.tags, self.data = [], []
        self.feed(text)
        self.close()

    def handle_starttag(self, tag, attrs):
        self.tags.append((tag, dict(attrs)))

    def handle_data(self, data):
        self.data.append(data)

    @property
    def text(self):
        return "".join(self.data)


def inert(html_text: str) -> Parsed:
    """The HTML parsed; fails on any element or attribute a page does not write itself."""
    p = Parsed(html_text)
    for tag, attrs in p.tags:
        assert tag in PAGE_TAGS, (tag, html_text)
        assert set(attrs) <= PAGE_ATTRS, (tag, attrs)
    return p


def test_esc_escapes_text_and_quoted_attributes():
    assert esc(IMG) == "&lt;img src=x onerror=alert(1)&gt;"
    assert esc(QUOTE) == "&quot;&#x27;&gt;&lt;svg onload=alert(2)&gt;"
    assert esc("a & b") == "a &amp; b" and esc(None) == "None" and esc(3) == "3"
    p = inert(f"<td title=\"{esc(QUOTE)}\">{esc(SCRIPT)}</td>")
    assert p.tags == [("td", {"title": QUOTE})] and p.text == SCRIPT


# ---------------------------------------------------------------------------------------------- pages
@pytest.fixture
def hostile_rig(tmp_path):
    """A store in a folder named IMG holding one capture of run IMG (object and source hostile too), and a
    'rig run' folder whose planner state and approval files carry hostile text everywhere."""
    folder = tmp_path / IMG
    folder.mkdir()
    store = folder / "s.db"
    with CaptureStore(store) as st:
        st.put(np.ones((3, 3, 128), np.int64), dict(object=QUOTE, class_group=IMG, size="8in", position=0, lights="off", repeat=0,
                                                    source=SCRIPT, capture_id=f"{IMG}/000000"),
               sensor=preset("tmf8828-3x3-short"),
               meta={"run_id": IMG, "step": 0, "commanded_mm": [0, 0], "reported_mm": [0, 0], "plan": SCRIPT})
    run = tmp_path / "run"
    run.mkdir()
    (run / "planner.json").write_text(json.dumps({
        "space": {"points_mm": [[0, 0], [100, 100], [200, 200]],
                  "excluded": [{"x_mm": 300.0, "y_mm": 300.0, "reason": SCRIPT}]},
        "proposals": [{"id": QUOTE, "index": 1, "x_mm": 100.0, "y_mm": 100.0, "status": "pending", "batch_order": 0}],
        "observations": [{"index": 0}], "failures": [{"index": 2, "id": IMG, "reason": SCRIPT}]}))
    return store, run


def divs(doc):
    from bokeh.models import Div

    return {m.name or f"#{i}": m.text for i, m in enumerate(doc.select({"type": Div}))}


def test_the_rig_page_shows_hostile_files_as_text(hostile_rig):
    from bokeh.document import Document

    from nlosplan.reports.live.rig_approval import ApprovalPanel
    from nlosplan.reports.live.rig_page import build_rig_document
    from nlosplan.reports.live.rig_watch import RigWatch

    store, run = hostile_rig
    req = post_request(run, run_id=IMG, batch=0, ids=[QUOTE])
    (run / "approval.json").write_text(json.dumps({**req, "budget_left": SCRIPT}))   # a peer's file
    watch = RigWatch(store, planner_dir=run, min_interval_s=0)
    doc = Document()
    panels = []

    def panel(d, w, m):
        panels.append(ApprovalPanel(d, w, m, allowed=lambda: (False, IMG)))
        return panels[-1]

    build_rig_document(doc, watch, approval=panel)
    panels[0].message = QUOTE
    panels[0].fill()
    shown = divs(doc)
    status = inert(shown["status"]).text
    assert f"capture store {store}" in status and f"run {IMG} · {QUOTE} 8in" in status and SCRIPT in status
    assert f"failed {IMG}: {SCRIPT}" in status
    approval = inert(shown["approval"]).text
    assert f"budget leaves {SCRIPT} more" in approval and f"read-only: {IMG}" in approval
    batch = inert(shown["batch"])
    assert QUOTE in batch.text and ("td", {"data-col": "id", "title": QUOTE}) in batch.tags   # the proposal id
    close_request(run, req, Answer("refuse", by=IMG), note=SCRIPT)  # answered: who and the note
    watch.refresh(force=True)
    panels[0].fill()
    answered = Parsed(divs(doc)["approval"])
    inert(divs(doc)["approval"])
    assert f"by {IMG} ({SCRIPT})" in answered.text
    for name, text in divs(doc).items():
        inert(text)
        for bad in (IMG, QUOTE, SCRIPT):
            assert bad not in text, name


def test_the_store_table_and_a_store_without_rig_runs(tmp_path):
    from bokeh.document import Document

    from nlosplan.reports.live.rig_page import build_rig_document
    from nlosplan.reports.live.rig_watch import RigWatch

    store = tmp_path / "s.db"
    with CaptureStore(store) as st:
        st.put(np.ones((3, 3, 128), np.int64), dict(object="A", size="8in", position=0, lights="off", repeat=0,
                                                    source=IMG), sensor=preset("tmf8828-3x3-short"))
    doc = Document()
    build_rig_document(doc, RigWatch(store, min_interval_s=0))
    table = inert(divs(doc)["store"])
    assert ("td", {"data-col": "source", "title": IMG}) in table.tags and IMG in table.text


def test_the_design_page_shows_a_hostile_folder_label_error_and_answer_as_text(tmp_path):
    from bokeh.document import Document

    from nlosplan.reports.live.design_page import build_design_document
    from nlosplan.reports.live.design_watch import DesignWatch

    out = tmp_path / IMG
    out.mkdir()
    (out / "design_checkpoint.json").write_text(json.dumps({"config": {"label": QUOTE}, "candidates": None}))
    (out / "design_evaluations.jsonl").write_text("")
    (out / "result.json").write_text(json.dumps({
        "cheapest": [{"requirement": SCRIPT, "task": IMG, "value": 0.5, "lo": 0.4, "hi": 0.6, QUOTE: IMG}],
        "requirements": [{"task": SCRIPT, "parameter": QUOTE, "minimum": IMG}]}))
    watch = DesignWatch(out, min_interval_s=0)
    doc = Document()
    build_design_document(doc, watch)
    shown = divs(doc)
    status = inert(shown["status"]).text
    assert f"design run {out} ({QUOTE})" in status
    assert watch.progress_error and IMG in watch.progress_error and watch.progress_error in status
    answer = inert(shown["answer"])
    assert SCRIPT in answer.text and ("td", {"data-col": QUOTE, "title": IMG}) in answer.tags
    params = inert(shown["parameters"]).text
    assert SCRIPT in params and QUOTE in params and IMG in params
    for name, text in shown.items():
        for bad in (IMG, QUOTE, SCRIPT):
            assert bad not in text, name


# ---------------------------------------------------------------------------------------------- logs
def record(msg, *args, exc=None, name="tornado.access"):
    return logging.LogRecord(name, logging.ERROR, __file__, 1, msg, args or None,
                             (type(exc), exc, None) if exc else None)


def test_the_log_filter_redacts_the_token_and_writes_one_line():
    tok = "s3cret-Token_42"
    f = Redact([tok])
    r = record("%d %s %.2fms", 500, f"GET /?x=1&token={tok}&y=2 (127.0.0.1)", 3.0)
    assert f.filter(r) and r.getMessage() == f"500 GET /?x=1&token={REDACTED}&y=2 (127.0.0.1) 3.00ms"
    r = record("Uncaught exception %s\n%r", f"GET /?token={tok}", {"arguments": {"token": [tok.encode()]}},
               exc=RuntimeError(f"boom {tok}"))
    assert f.filter(r)
    text = r.getMessage()
    assert tok not in text and "\n" not in text and r.exc_info is None and "[RuntimeError: boom [redacted]]" in text
    assert redact("token=abc def Token=xyz&k=1 notoken=v") == f"token={REDACTED} def Token={REDACTED}&k=1 notoken=v"
    r = record("message %r", "\x1b[2J\x07bell")
    assert f.filter(r) and "\x1b" not in r.getMessage() and "\\x1b[2J\\x07bell" in r.getMessage()
    r = record("%s", "x" * 5000)
    assert f.filter(r) and len(r.getMessage()) == 400
    r = record("Refusing websocket connection from Origin '%s'; use --allow-websocket-origin=%s", "http://e.vil:1", "x")
    assert f.filter(r) and r.getMessage() == ("refused a websocket from a page at http://e.vil:1: not an allowed "
                                              "origin (nlosplan serve --allow-origin HOST:PORT adds one)")


def test_the_log_filter_drops_a_flood_and_says_so():
    now = [0.0]
    f = Redact([], burst=3, window_s=10.0, clock=lambda: now[0])
    passed = [f.filter(record("m%d", i)) for i in range(10)]
    assert passed == [True] * 3 + [False] * 7
    now[0] = 10.0
    r = record("next")
    assert f.filter(r) and r.getMessage() == "next (7 earlier log lines dropped: more than 3 in 10 s)"


def test_server_logs_route_the_libraries_and_restore_them():
    root, tornado = logging.getLogger(), logging.getLogger("tornado")
    before = (root.handlers[:], tornado.handlers[:], tornado.level, tornado.propagate)
    out = io.StringIO()
    with server_logs(["tok-12345678"], stream=out):
        logging.getLogger("tornado.application").error("Uncaught exception GET /?token=tok-12345678\nline two")
        logging.getLogger("bokeh.server.views.ws").info("WebSocket connection opened")   # below ERROR: not shown
        logging.getLogger("somelib").warning("a warning with tok-12345678")
    assert out.getvalue().splitlines() == [
        f"nlosplan serve: tornado.application: Uncaught exception GET /?token={REDACTED} line two",
        f"nlosplan serve: somelib: a warning with {REDACTED}"]
    assert (root.handlers, tornado.handlers, tornado.level, tornado.propagate) == before


class Served:
    """:func:`serve` in a thread (no signal handlers there), stopped by :meth:`stop`."""

    def __init__(self, page, **kw):
        self.sock = bind("127.0.0.1", 0)
        self.port = self.sock.getsockname()[1]
        self.log = io.StringIO()
        self.done = threading.Event()
        self.ready = threading.Event()
        self._stop = False
        self.thread = threading.Thread(target=self._run, args=(page, kw), daemon=True)
        self.thread.start()
        assert self.ready.wait(60)

    def _run(self, page, kw):
        try:
            serve(self.sock, page, stop=lambda: self._stop, on_ready=self.ready.set, log_stream=self.log, **kw)
        finally:
            self.done.set()

    def get(self, query=""):
        try:
            return urllib.request.urlopen(f"http://127.0.0.1:{self.port}/{query}", timeout=60).status
        except urllib.error.HTTPError as exc:
            return exc.code

    def stop(self):
        self._stop = True
        assert self.done.wait(30)


def store_with_capture(path):
    with CaptureStore(path) as st:
        st.put(np.ones((3, 3, 128), np.int64), dict(object="A", size="8in", position=0, lights="off", repeat=0,
                                                    source="rig", capture_id="r/000000"),
               sensor=preset("tmf8828-3x3-short"), meta={"run_id": "r", "step": 0, "commanded_mm": [0, 0]})
    return path


def test_a_500_on_a_url_with_the_token_is_logged_without_it(tmp_path, monkeypatch):
    token = "Tk-" + "q" * 20
    store = store_with_capture(tmp_path / "s.db")
    (tmp_path / "run").mkdir()

    def broken(doc, watch, **kw):
        raise RuntimeError(f"a page that fails with its URL's token {token} in the message")

    monkeypatch.setattr("nlosplan.reports.live.rig_page.build_rig_document", broken)
    srv = Served(Page("rig", store, planner_dir=tmp_path / "run", actions=True, token=token))
    try:
        assert srv.get(f"?token={token}&x=1") == 500
    finally:
        srv.stop()
    lines = srv.log.getvalue().splitlines()
    assert lines and token not in srv.log.getvalue() and "Traceback" not in srv.log.getvalue()
    assert any(f"GET /?token={REDACTED}&x=1" in line and line.startswith("nlosplan serve: tornado.") for line in lines)
    assert all(line.startswith("nlosplan serve: ") for line in lines)


def test_unused_sessions_are_dropped_and_their_number_capped(tmp_path, monkeypatch):
    from bokeh.models import Div

    built, destroyed = [], []

    def counting(doc, watch, **kw):   # the sessions' life is the subject here, not the page: a cheap one
        built.append(doc)
        doc.on_session_destroyed(lambda ctx: destroyed.append(ctx.id))
        doc.add_root(Div(text="page"))

    monkeypatch.setattr("nlosplan.reports.live.rig_page.build_rig_document", counting)
    token = "cap-test-token"
    (tmp_path / "run").mkdir()
    page = Page("rig", store_with_capture(tmp_path / "s.db"), planner_dir=tmp_path / "run", actions=True, token=token)
    # the cap: two sessions (none expires during the test); the third request gets the one-line page, a request
    # with the token still gets the rig page
    monkeypatch.setattr(live_server, "MAX_SESSIONS", 2)
    monkeypatch.setattr(live_server, "UNUSED_SESSION_S", 600.0)
    srv = Served(page)
    try:
        assert [srv.get() for _ in range(3)] == [200, 200, 200] and len(built) == 2
        assert srv.get(f"?token={token}") == 200 and len(built) == 3
    finally:
        srv.stop()
    # expiry: sessions no browser connects to are dropped within the lifetime and the check period
    monkeypatch.setattr(live_server, "MAX_SESSIONS", 32)
    monkeypatch.setattr(live_server, "UNUSED_SESSION_S", 1.0)
    monkeypatch.setattr(live_server, "CHECK_UNUSED_S", 0.2)
    built.clear()
    srv = Served(page)
    try:
        assert [srv.get() for _ in range(4)] == [200] * 4 and len(built) == 4
        deadline = time.monotonic() + 30
        while len(destroyed) < 4 and time.monotonic() < deadline:
            time.sleep(0.1)
        assert len(destroyed) == 4
    finally:
        srv.stop()


# ---------------------------------------------------------------------------------------------- CLI
def one_line_error(capsys, argv, *must):
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1, err
    for m in must:
        assert m in err, err
    return err


def test_serve_takes_the_token_from_a_file_or_stdin_never_argv(tmp_path, capsys, monkeypatch):
    from nlosplan.cli.serve import read_token

    store = store_with_capture(tmp_path / "s.db")
    (tmp_path / "run").mkdir()
    run = str(tmp_path / "run")
    err = one_line_error(capsys, ["serve", str(store), "--planner", run, "--token", "long-enough-token"],
                         "(ps)", "--token -", "--token-file PATH")
    assert "long-enough-token" not in err
    one_line_error(capsys, ["serve", str(store), "--token", "-", "--token-file", "x"], "exclude each other")
    one_line_error(capsys, ["serve", str(store), "--token-file", "x", "--no-token"], "exclude each other")
    one_line_error(capsys, ["serve", str(store), "--token-file", str(tmp_path / "nope")], "applies only to a page "
                                                                                         "with actions")
    one_line_error(capsys, ["serve", str(store), "--planner", run, "--token-file", str(tmp_path / "nope")],
                   "cannot read it (No such file or directory)")
    (tmp_path / "short").write_text("short\n")
    err = one_line_error(capsys, ["serve", str(store), "--planner", run, "--token-file", str(tmp_path / "short")],
                         "8 to 256 characters", "has 5 characters")
    assert "short\n" not in err.split("--token-file")[1].replace(str(tmp_path / "short"), "")
    (tmp_path / "spaces").write_text("has spaces inside\n")
    one_line_error(capsys, ["serve", str(store), "--planner", run, "--token-file", str(tmp_path / "spaces")],
                   "each a letter, a digit")
    (tmp_path / "good").write_text("  good.token_~-1  \nsecond line ignored\n")
    assert read_token(None, str(tmp_path / "good")) == "good.token_~-1"
    assert read_token("-", None, stdin=io.StringIO("piped-token-1\n")) == "piped-token-1"
    assert read_token(None, None) is None
    monkeypatch.setattr("sys.stdin", io.StringIO(""))
    one_line_error(capsys, ["serve", str(store), "--planner", run, "--token", "-"], "--token - (stdin): no token")


def test_serve_checks_poll_and_allow_origin_before_any_work(tmp_path, capsys):
    store = str(store_with_capture(tmp_path / "s.db"))
    for bad in ("1e-9", "0", "-1", "nan", "inf", "1e308", "3601"):
        one_line_error(capsys, ["serve", store, "--poll", bad], "argument --poll", "allowed: 0.05 to 3600 seconds")
    for bad in ("*:8050", "http://rig-pc:8050", "rig pc", "rig-pc:0", "rig-pc:70000", "rig-pc/x", ""):
        one_line_error(capsys, ["serve", store, "--allow-origin", bad], "--allow-origin")
    assert parse_origin("Rig-PC", 8050) == "rig-pc:8050" and parse_origin("[::1]:9000", 1) == "[::1]:9000"


def test_the_websocket_origins_are_explicit():
    import socket

    assert websocket_origins("127.0.0.1", 8050) == ["127.0.0.1:8050", "localhost:8050", "[::1]:8050"]
    assert websocket_origins("10.1.2.3", 8050, ["rig-pc:8050"]) == ["10.1.2.3:8050", "rig-pc:8050"]
    every = websocket_origins("0.0.0.0", 8050)
    assert every[:3] == ["127.0.0.1:8050", "localhost:8050", "[::1]:8050"]
    assert f"{socket.gethostname().lower()}:8050" in every
    assert all("*" not in o and o.endswith(":8050") for o in every + websocket_origins("::", 8050))


def start_serve(argv, stdin=None):
    proc = subprocess.Popen([sys.executable, "-m", "nlosplan", "serve", *argv, "--port", "0"], stdin=stdin,
                            stderr=subprocess.PIPE, text=True, env=ENV)
    err: list[str] = []
    threading.Thread(target=lambda: err.extend(proc.stderr), daemon=True).start()
    deadline = time.monotonic() + 120
    while True:
        m = re.search(r"at (http://127\.0\.0\.1:(\d+)/\S*)", "".join(err))
        if m:
            break
        assert proc.poll() is None and time.monotonic() < deadline, "".join(err)
        time.sleep(0.1)
    while True:   # serving (its signal handlers set) once it answers
        try:
            urllib.request.urlopen(f"http://127.0.0.1:{m.group(2)}/static/js/bokeh.min.js", timeout=60).read(1)
            return proc, err, m.group(1), int(m.group(2))
        except OSError:
            assert proc.poll() is None and time.monotonic() < deadline, "".join(err)
            time.sleep(0.2)


def test_a_served_page_keeps_its_token_out_of_ps_and_logs_and_answers_bad_traffic_in_one_line_each(tmp_path):
    """``serve`` with --token-file: the token is not on its command line and no log line shows it; malformed
    websocket messages and a page of another origin get one line each (98 traceback lines from 6 messages
    before), Ctrl-C ends it with 130."""
    from tornado.httpclient import HTTPClientError, HTTPRequest
    from tornado.websocket import websocket_connect

    store = store_with_capture(tmp_path / "s.db")
    (tmp_path / "run").mkdir()
    token = "file-token-0123456789"
    (tmp_path / "tok").write_text(token + "\n")
    proc, err, url, port = start_serve([str(store), "--planner", str(tmp_path / "run"), "--token-file",
                                        str(tmp_path / "tok")])
    try:
        assert url.endswith(f"?token={token}")                        # the URL the user opens: their terminal
        assert token.encode() not in Path(f"/proc/{proc.pid}/cmdline").read_bytes()
        html = urllib.request.urlopen(url, timeout=120).read().decode()
        session_token = re.search(r'"token":\s*"([^"]+)"', html).group(1)
        n0 = len("".join(err).splitlines())

        async def talk():
            answers = []
            for origin, messages in ((f"http://127.0.0.1:{port}", [b"\x00\xff" * 8]),
                                     (f"http://127.0.0.1:{port}", ["{}", "x", "y"]),
                                     (f"http://127.0.0.1:{port}", ['{"msgtype":"PATCH-DOC","msgid":"1"}', "{}", "{}"]),
                                     ("http://rebound.example:%d" % port, ["{}"])):
                try:
                    ws = await websocket_connect(HTTPRequest(f"ws://127.0.0.1:{port}/ws", headers={"Origin": origin}),
                                                 subprotocols=["bokeh", session_token])
                except HTTPClientError as exc:
                    answers.append(exc.code)
                    continue
                for m in messages:
                    await ws.write_message(m, binary=isinstance(m, bytes))
                answers.append(await asyncio.wait_for(ws.read_message(), 60) is not None)
                ws.close()
            return answers

        answers = asyncio.run(talk())
        assert answers[-1] == 403                      # the other origin: refused
        time.sleep(1.0)
    finally:
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=60) == 130
    lines = "".join(err).splitlines()
    assert lines[-1] == "nlosplan serve: stopped (SIGINT)"
    assert [l for l in lines if token in l] == [l for l in lines if l.startswith("nlosplan serve: rig page of")]
    bad = lines[n0:-1]
    assert 3 <= len(bad) <= 12, bad                    # about one line per bad message
    assert all(l.startswith("nlosplan serve: ") for l in bad), bad
    assert not any("Traceback" in l for l in bad)
    assert any("refused a websocket from a page at http://rebound.example" in l for l in bad)
