"""``--live`` of ``design``, ``rig capture`` and ``rig run``: the live page of the run in progress.

The port is bound here, before any work (a port in use is a one-line error),
and handed to a child process (``python -m nlosplan.cli.live``) that serves
the page (:mod:`nlosplan.reports.live.server`) at a lower priority
(``nice`` 10): the page reads the files the run writes and never shares the
run's interpreter, so it cannot block or slow it. The child ends with the
run (and by itself if the run dies). Its settings, the token included, go
through a pipe, not the command line (which other users can list).

Also here: the approval prompt of ``rig run --approve``, which waits for the
first answer from the terminal or from a page (:mod:`nlosplan.planner.capture.approval`).
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
import subprocess
import sys
from pathlib import Path

from nlosplan.errors import UserError
from nlosplan.schema import parse_int

__all__ = ["LiveView", "add_live_option", "ask_approval", "live_page"]

DEFAULT_PORT = 8050


def _address(text: str) -> tuple[str, int]:
    host, sep, port = text.rpartition(":")
    host = host.strip("[]") if sep else "127.0.0.1"
    try:
        p = parse_int(port)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: give PORT or HOST:PORT, e.g. 8050 or 0.0.0.0:8050") from None
    if not 0 <= p <= 65535:
        raise argparse.ArgumentTypeError(f"port {p} is out of range; allowed: 0 to 65535")
    return host or "127.0.0.1", p


def add_live_option(p: argparse.ArgumentParser, what: str) -> None:
    """``--live [[HOST:]PORT]``."""
    p.add_argument("--live", nargs="?", const=("127.0.0.1", DEFAULT_PORT), default=None, type=_address,
                   metavar="[HOST:]PORT",
                   help=f"serve a live web page of {what} while it runs (default 127.0.0.1:{DEFAULT_PORT}; "
                        "the URL is printed; see 'nlosplan serve')")


class LiveView:
    """The live page of a run, in a child process (a context manager; the page ends with the block).

    Parameters
    ----------
    address : (host, port)
        From ``--live``.
    kind : {"design", "rig"}
    path : path
        The design output folder or the capture store.
    planner_dir : path, optional
        ``rig run``: its output folder.
    run_id : str, optional
    actions : bool
        Whether the page may answer the approval gate (``rig run --approve``); then a token is made.
    quiet : bool
        Print nothing (the URL is still in :attr:`url`).
    """

    def __init__(self, address, kind: str, path, *, planner_dir=None, run_id=None, actions: bool = False,
                 quiet: bool = False, poll_s: float = 1.0):
        from nlosplan.reports.live.server import bind, is_loopback, page_url

        self.host, port = address
        self.token = secrets.token_urlsafe(16) if actions else None
        self.sock = bind(self.host, port)   # a port in use fails here, before the run starts
        self.port = self.sock.getsockname()[1]
        self.url = page_url(self.host, self.port, self.token)
        self.config = {"kind": kind, "path": str(path), "planner_dir": None if planner_dir is None else str(planner_dir),
                       "run_id": run_id, "actions": bool(actions), "token": self.token, "poll_ms": int(1000 * poll_s),
                       "parent": os.getpid(), "fd": self.sock.fileno()}
        self.quiet = quiet
        self.proc = None
        if not is_loopback(self.host) and not quiet:
            print(f"nlosplan: live page listens on {self.host} (other machines can reach it)", file=sys.stderr)

    def __enter__(self) -> "LiveView":
        self.proc = subprocess.Popen([sys.executable, "-m", "nlosplan.cli.live"], stdin=subprocess.PIPE,
                                     stdout=subprocess.DEVNULL, pass_fds=(self.sock.fileno(),), close_fds=True)
        self.proc.stdin.write(json.dumps(self.config).encode())
        self.proc.stdin.close()
        self.sock.close()   # the child holds it now
        if not self.quiet:
            print(f"nlosplan: live page at {self.url}" + ("  (the token lets the page approve batches: keep it "
                                                           "private)" if self.token else ""), file=sys.stderr,
                  flush=True)
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self.proc is None:
            self.sock.close()
            return
        if self.proc.poll() is None:
            self.proc.terminate()
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.proc = None


def live_page(args, kind: str, path, **kw):
    """A :class:`LiveView` when the command has ``--live`` (its port bound now), else a context that does nothing."""
    from contextlib import nullcontext

    if getattr(args, "live", None) is None:
        return nullcontext()
    return LiveView(args.live, kind, path, **kw)


def ask_approval(request: dict, out, *, live: bool, stdin=None, poll_s: float = 0.2):
    """Wait for the first answer to an approval request: a line on the terminal (y/yes approves, anything
    else refuses) or an answer file written by a page. Returns the :class:`Answer`.

    Without a page (``live`` false) the end of stdin refuses, as a plain prompt does; with a page, the
    end of stdin leaves the answer to the page.
    """
    import select

    from nlosplan.planner.capture.approval import Answer, read_answer, submit_answer

    stdin = sys.stdin if stdin is None else stdin
    rid = request["request_id"]
    try:
        fd = stdin.fileno()
    except (AttributeError, OSError, ValueError):
        fd = None
    reading = True
    while True:
        got = read_answer(out, rid)
        if got is not None:
            if got.by != "terminal":
                print(f"\nanswered on the live page: {got.decision}" + (" (edited)" if got.edited else ""),
                      file=sys.stderr, flush=True)
            return got
        line = None
        if reading and fd is None:
            line = stdin.readline()       # no file descriptor (a test's StringIO): a blocking read
        elif reading:
            ready, _, _ = select.select([fd], [], [], poll_s)
            if ready:
                line = stdin.readline()
        else:
            import time

            time.sleep(poll_s)
        if line is None:
            continue
        if line == "" and live:
            reading = False               # stdin ended (no terminal): the page answers
            print("\n(no terminal input: answer on the live page)", file=sys.stderr, flush=True)
            continue
        answer = Answer("approve" if line.strip().lower() in ("y", "yes") else "refuse", by="terminal")
        if submit_answer(out, rid, answer):
            return answer


def _child() -> int:
    """The page's process: settings from stdin, the inherited socket, served until the parent ends or
    stops it (SIGTERM, taken by the server's event loop between callbacks: exit 143)."""
    import socket

    from nlosplan.reports.live.server import Page, serve

    cfg = json.loads(sys.stdin.read())
    try:
        os.nice(10)
    except OSError:
        pass
    sock = socket.socket(fileno=cfg["fd"])
    sock.setblocking(False)
    page = Page(cfg["kind"], Path(cfg["path"]), planner_dir=None if cfg["planner_dir"] is None
                else Path(cfg["planner_dir"]), run_id=cfg["run_id"], actions=cfg["actions"], token=cfg["token"])
    parent = int(cfg["parent"])
    try:
        sig = serve(sock, page, poll_ms=cfg["poll_ms"], stop=lambda: os.getppid() != parent,
                    log_prefix="nlosplan: live page")
    except UserError as exc:
        print(f"nlosplan: live page: {exc}", file=sys.stderr)
        return 2
    return 0 if sig is None else 128 + int(sig)   # the run's SIGTERM at its end: 143


if __name__ == "__main__":
    sys.exit(_child())
