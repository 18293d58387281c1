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
"""

from __future__ import annotations

import errno
import hmac
import ipaddress
import logging
import socket
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from nlosplan.errors import UserError

__all__ = ["Page", "bind", "is_loopback", "page_url", "serve"]


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


def _origins(host: str, port: int) -> list[str]:
    if is_loopback(host):
        return [f"127.0.0.1:{port}", f"localhost:{port}", f"[::1]:{port}"]
    if host in ("", "0.0.0.0", "::"):
        return [f"*:{port}"]  # any name of this machine; acting still needs the token
    return [f"{host}:{port}"]


def _session_allowed(doc, page: Page, watch) -> tuple[bool, str]:
    if not page.actions:
        return False, "this page was started read-only"
    if watch.opened and not watch.writable:
        return False, "the store is archived (read-only): no actions"
    if page.token is None:
        return True, ""
    args = doc.session_context.request.arguments if doc.session_context else {}
    given = (args.get("token") or [b""])[0]
    given = given.decode("utf-8", "replace") if isinstance(given, bytes) else str(given)
    if hmac.compare_digest(given.encode(), page.token.encode()):
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


def serve(sock: socket.socket, page: Page, *, poll_ms: int = 1000, stop: Callable[[], bool] | None = None,
          on_ready: Callable[[], None] | None = None) -> None:
    """Serve ``page`` on a bound socket until ``stop()`` returns true (polled every second) or Ctrl-C.

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
    """
    import asyncio

    from bokeh.application import Application
    from bokeh.application.handlers.function import FunctionHandler
    from bokeh.server.server import BaseServer
    from bokeh.server.tornado import BokehTornado
    from tornado.httpserver import HTTPServer
    from tornado.ioloop import IOLoop, PeriodicCallback

    for name in ("bokeh", "tornado"):
        logging.getLogger(name).setLevel(logging.ERROR)
    watch = make_watch(page, poll_ms / 1000.0)

    def session(doc) -> None:
        if page.kind == "design":
            from nlosplan.reports.live.design_page import build_design_document

            build_design_document(doc, watch, poll_ms=poll_ms)
            return
        from nlosplan.reports.live.rig_approval import ApprovalPanel
        from nlosplan.reports.live.rig_page import build_rig_document

        def panel(d, w, m):
            return ApprovalPanel(d, w, m, allowed=lambda: _session_allowed(doc, page, w))

        build_rig_document(doc, watch, approval=panel if page.planner_dir is not None else None, poll_ms=poll_ms)

    asyncio.set_event_loop(asyncio.new_event_loop())
    loop = IOLoop.current()
    host, port = sock.getsockname()[:2]
    app = BokehTornado({"/": Application(FunctionHandler(session))}, extra_websocket_origins=_origins(host, port))
    http = HTTPServer(app, xheaders=False)
    http.add_sockets([sock])
    server = BaseServer(loop, app, http)
    server.start()
    if stop is not None:
        PeriodicCallback(lambda: loop.stop() if stop() else None, 1000).start()
    if on_ready is not None:
        loop.add_callback(on_ready)
    try:
        loop.start()
    finally:
        server.stop()
        http.stop()
        if hasattr(watch, "close"):
            watch.close()
