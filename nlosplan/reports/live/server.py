"""The live view's web server: a Bokeh server on one bound socket, serving the design or the rig page.

Every browser session gets its own document; all sessions share one watch
(:class:`~nlosplan.reports.live.design_watch.DesignWatch` or
:class:`~nlosplan.reports.live.rig_watch.RigWatch`), which reads the run's
files at most once per poll interval whatever the number of pages open.
BokehJS is served by the server itself (no network needed). Safety: the
socket is bound where the caller says (``127.0.0.1`` unless told
otherwise); a session may act (answer the approval gate, which moves the
gantry) only when the page allows actions, the store is writable, and the
session's URL carries the token (``?token=...``), compared in constant time.
Pages from other origins cannot open the websocket (an explicit list of
``host:port``, never a wildcard: :func:`websocket_origins`); unused sessions
are dropped within seconds and their number is capped; the server's log lines
are single lines with the token redacted (:mod:`~nlosplan.reports.live.logs`);
SIGTERM and SIGINT stop the event loop between callbacks.
"""

from __future__ import annotations

import errno
import hmac
import ipaddress
import re
import socket
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from nlosplan.errors import UserError

__all__ = ["CHECK_UNUSED_S", "MAX_MESSAGE_BYTES", "MAX_SESSIONS", "POLL_RANGE_S", "UNUSED_SESSION_S", "Page", "bind",
           "is_loopback", "page_url", "parse_origin", "serve", "websocket_origins"]


#: ``--poll`` (seconds between reads of the run's files): from 0.05 s (20 reads a second) to an hour.
POLL_RANGE_S = (0.05, 3600.0)
#: Sessions (pages built) at most; past it a request without the token gets a one-line page.
MAX_SESSIONS = 32
#: A session no browser is connected to is dropped this long after its last connection ended (or it was made).
UNUSED_SESSION_S = 5.0
#: How often unused sessions are looked for.
CHECK_UNUSED_S = 2.5
#: The largest websocket message a browser may send (a page sends clicks and edits, a few hundred bytes).
MAX_MESSAGE_BYTES = 1 << 20


@dataclass(frozen=True)
class Page:
    """What a server shows.

    Attributes
    ----------
    kind : {"design", "rig"}
    path : Path
        The design output folder, or the capture store.
    planner_dir : Path, optional
        Rig page: the ``rig run`` output folder (planner checkpoint, approval gate).
    run_id : str, optional
        Rig page: the run to show (default: the newest).
    actions : bool
        Whether a session with the token may answer the approval gate.
    token : str, optional
        The token a session's URL must carry to act; None: no token asked (loopback only).
    """

    kind: str
    path: Path
    planner_dir: Path | None = None
    run_id: str | None = None
    actions: bool = False
    token: str | None = None


def is_loopback(host: str) -> bool:
    """Whether ``host`` names this machine only (127.0.0.0/8, ::1, localhost)."""
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host).is_loopback
    except ValueError:
        return False


def bind(host: str, port: int) -> socket.socket:
    """A listening TCP socket on ``host:port`` (port 0: any free port).

    Raises
    ------
    UserError
        The port is in use, or the address cannot be bound here.
    """
    try:
        infos = socket.getaddrinfo(host, port, type=socket.SOCK_STREAM, flags=socket.AI_PASSIVE)
    except socket.gaierror as exc:
        raise UserError(f"--host {host}: {exc.strerror}") from None
    family, kind, proto, _, addr = infos[0]
    sock = socket.socket(family, kind, proto)
    sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
    try:
        sock.bind(addr)
        sock.listen(64)
    except OSError as exc:
        sock.close()
        if exc.errno == errno.EADDRINUSE:
            raise UserError(f"port {port} on {host} is in use; choose another with --port (0: any free port)") from None
        raise UserError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from None
    sock.setblocking(False)
    return sock


def page_url(host: str, port: int, token: str | None = None) -> str:
    """The URL to open (with ``?token=`` when actions need it)."""
    shown = "127.0.0.1" if host in ("", "0.0.0.0") else "::1" if host == "::" else host
    if ":" in shown:
        shown = f"[{shown}]"
    return f"http://{shown}:{port}/" + (f"?token={token}" if token else "")


_ORIGIN = re.compile(r"(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9.-]+)(?::([0-9]{1,5}))?")


def _netloc(host: str, port: int) -> str:
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def websocket_origins(host: str, port: int, allow=()) -> list[str]:
    """The ``host:port`` origins whose pages may open the websocket (every other origin is refused).

    Parameters
    ----------
    host : str
        The address served (``--host``).
    port : int
        The port served.
    allow : iterable of str
        More origins, ``HOST:PORT`` each (``--allow-origin``, checked by :func:`parse_origin`).

    Returns
    -------
    list of str
        A loopback host: ``127.0.0.1``, ``localhost`` and ``[::1]`` at ``port``; another host: that host at
        ``port``; every interface (``0.0.0.0``, ``::``): the loopback names and this machine's own names
        (``socket.gethostname()`` and its fully qualified name) at ``port``; then ``allow``. Never a
        wildcard: a page served from any other name (a DNS-rebinding site resolving to this machine) cannot
        talk to the server.
    """
    loop = ["127.0.0.1", "localhost", "::1"]
    if is_loopback(host):
        names = loop
    elif host in ("", "0.0.0.0", "::"):
        own = [socket.gethostname(), socket.getfqdn()]
        names = loop + [n.lower() for n in own if n and n not in loop]
    else:
        names = [host.lower()]
    out = [_netloc(n, port) for n in names]
    for a in allow:
        if a not in out:
            out.append(a)
    return out


def parse_origin(text: str, port: int) -> str:
    """``--allow-origin HOST[:PORT]`` as ``host:port`` (the port served when none is given).

    Raises
    ------
    UserError
        A scheme, a path, a wildcard, an empty host or a bad port.
    """
    m = _ORIGIN.fullmatch(text.strip())
    if m is None:
        raise UserError(f"--allow-origin {text!r}: give HOST or HOST:PORT as a browser's address bar shows it, "
                        "e.g. rig-pc:8050 or 192.168.1.20:8050 (no scheme, path or wildcard)")
    host, p = m.group(1), int(m.group(2)) if m.group(2) else port
    if not 1 <= p <= 65535:
        raise UserError(f"--allow-origin {text!r}: port {p} is out of range; allowed: 1 to 65535")
    return f"{host.lower()}:{p}"


def _session_allowed(doc, page: Page, watch) -> tuple[bool, str]:
    if not page.actions:
        return False, "this page was started read-only"
    if watch.opened and not watch.writable:
        return False, "the store is archived (read-only): no actions"
    if page.token is None or _token_given(doc, page):
        return True, ""
    return False, "open the URL with the token printed on the run's terminal to approve, edit or refuse"


def make_watch(page: Page, poll_s: float):
    """The shared watch of a page (raises UserError when the path is not what the page needs)."""
    if page.kind == "design":
        from nlosplan.reports.live.design_watch import DesignWatch

        return DesignWatch(page.path, min_interval_s=poll_s)
    if page.kind == "rig":
        from nlosplan.reports.live.rig_watch import RigWatch

        return RigWatch(page.path, planner_dir=page.planner_dir, run_id=page.run_id, min_interval_s=poll_s)
    raise UserError(f"unknown live page {page.kind!r}; allowed: design, rig")


def _token_given(doc, page: Page) -> bool:
    if page.token is None:
        return False
    args = doc.session_context.request.arguments if doc.session_context else {}
    given = (args.get("token") or [b""])[0]
    given = given.decode("utf-8", "replace") if isinstance(given, bytes) else str(given)
    return hmac.compare_digest(given.encode(), page.token.encode())


def _too_many(doc, page: Page) -> bool:
    """Whether this new session would pass :data:`MAX_SESSIONS` (a session with the token never is)."""
    ctx = doc.session_context
    if ctx is None or _token_given(doc, page):
        return False
    return len(ctx.server_context.sessions) >= MAX_SESSIONS


def serve(sock: socket.socket, page: Page, *, poll_ms: int = 1000, stop: Callable[[], bool] | None = None,
          on_ready: Callable[[], None] | None = None, allow_origins=(), log_stream=None,
          log_prefix: str = "nlosplan serve") -> int | None:
    """Serve ``page`` on a bound socket until ``stop()`` returns true (polled every second), SIGTERM or SIGINT.

    Parameters
    ----------
    sock : socket.socket
        Listening socket (:func:`bind`).
    page : Page
    poll_ms : int
        How often each page asks for changes, ms (the files are read at most this often).
    stop : callable, optional
    on_ready : callable, optional
        Called once the server accepts connections.
    allow_origins : iterable of str
        Origins (``host:port``) allowed besides the names of the address served (:func:`websocket_origins`).
    log_stream : file, optional
        Where the server's log lines go (default: stderr); one line each, the token redacted
        (:func:`~nlosplan.reports.live.logs.server_logs`).
    log_prefix : str
        What each log line starts with.

    Returns
    -------
    int or None
        The signal that stopped the server (``signal.SIGTERM`` or ``signal.SIGINT``), None when ``stop()``
        did. In the main thread the signals are taken by the event loop (asyncio's signal handlers): they
        stop the loop between callbacks, never raise inside whatever code runs when they arrive.

    Notes
    -----
    Sessions: a session no browser is connected to is dropped :data:`UNUSED_SESSION_S` seconds after its
    last connection ended (or after it was made, for a plain GET), checked every
    :data:`CHECK_UNUSED_S` seconds; past :data:`MAX_SESSIONS` sessions a request without the token gets a
    one-line page saying so instead of a new rig or design page. A websocket message is at most
    :data:`MAX_MESSAGE_BYTES`.
    """
    import asyncio
    import signal
    import threading

    from bokeh.application import Application
    from bokeh.application.handlers.function import FunctionHandler
    from bokeh.server.server import BaseServer
    from bokeh.server.tornado import BokehTornado
    from tornado.httpserver import HTTPServer
    from tornado.ioloop import IOLoop, PeriodicCallback

    from nlosplan.reports.live.logs import server_logs

    watch = make_watch(page, poll_ms / 1000.0)

    def session(doc) -> None:
        if _too_many(doc, page):
            from bokeh.models import Div

            doc.add_root(Div(text=f"<p>this page is open in {MAX_SESSIONS} browser sessions already: close some "
                                  "and reload</p>", name="too_many"))
            return
        if page.kind == "design":
            from nlosplan.reports.live.design_page import build_design_document

            build_design_document(doc, watch, poll_ms=poll_ms)
            return
        from nlosplan.reports.live.rig_approval import ApprovalPanel
        from nlosplan.reports.live.rig_page import build_rig_document

        def panel(d, w, m):
            return ApprovalPanel(d, w, m, allowed=lambda: _session_allowed(doc, page, w))

        build_rig_document(doc, watch, approval=panel if page.planner_dir is not None else None, poll_ms=poll_ms)

    stopped_by: list[int] = []
    with server_logs([page.token] if page.token else [], stream=log_stream, prefix=log_prefix):
        aloop = asyncio.new_event_loop()
        asyncio.set_event_loop(aloop)
        loop = IOLoop.current()
        host, port = sock.getsockname()[:2]
        app = BokehTornado({"/": Application(FunctionHandler(session))},
                           extra_websocket_origins=websocket_origins(host, port, allow_origins),
                           unused_session_lifetime_milliseconds=int(1000 * UNUSED_SESSION_S),
                           check_unused_sessions_milliseconds=int(1000 * CHECK_UNUSED_S),
                           websocket_max_message_size_bytes=MAX_MESSAGE_BYTES)
        http = HTTPServer(app, xheaders=False)
        http.add_sockets([sock])
        server = BaseServer(loop, app, http)
        server.start()
        signals = []
        if threading.current_thread() is threading.main_thread():
            for sig in (signal.SIGTERM, signal.SIGINT):
                aloop.add_signal_handler(sig, lambda s=sig: (stopped_by.append(s), loop.stop()))
                signals.append(sig)
        if stop is not None:
            PeriodicCallback(lambda: loop.stop() if stop() else None, 1000).start()
        if on_ready is not None:
            loop.add_callback(on_ready)
        try:
            loop.start()
        finally:
            for sig in signals:
                aloop.remove_signal_handler(sig)
            server.stop()
            http.stop()
            if hasattr(watch, "close"):
                watch.close()
    return stopped_by[0] if stopped_by else None
