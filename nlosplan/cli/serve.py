"""``nlosplan serve PATH``: the live view of a design output folder or a capture store (finished or running)."""

from __future__ import annotations

import json
import re
import secrets
import sys
from pathlib import Path

from nlosplan.cli.common import int_type, sub_parser
from nlosplan.errors import UserError

DEFAULT_PORT = 8050

DESCRIPTION = """\
Serve a web page over the files a run writes, and keep it up to date while the
run goes on (a finished run's page shows its end). PATH is:

- a design output folder (nlosplan design --out): stage and progress, the answer
  so far, trade-off plots (hover a point for its design), the evaluators' error
  against run time;
- a capture store: the rig page of its newest rig run (or --run): the rig map,
  the last histogram of every zone, captures stored / planned / left, faults;
  with --planner DIR (a 'rig run --out' folder) also the planner's route,
  localization RMSE and calibration, and the approval gate of 'rig run --approve';
- a 'rig run --out' folder of a finished run (its rig_run.json names the store).

The page reads the files (SQLite read-only) and writes nothing, except an
answer to the approval gate. Safety: it listens on 127.0.0.1 unless --host says
otherwise; approving, editing or refusing a batch (which moves the gantry) needs
the token of the URL printed here (a new random one, or yours from --token-file
or --token - on stdin; never on the command line, where ps shows it); a store
that cannot be written (an archive) and --read-only give pages without actions.
Only pages opened at the address served (and --allow-origin ones) can talk to
the server; whatever the run's files hold is shown as text. SIGTERM or Ctrl-C
stop it (exit 143 or 130). --live on design, rig capture and rig run starts the
same page for the run in progress."""


def _host(text: str) -> str:
    if not text or any(c.isspace() for c in text):
        raise UserError(f"--host {text!r}: give an address such as 127.0.0.1, 0.0.0.0 or a host name")
    return text


def resolve_page(path, *, planner=None, run=None, read_only=False):
    """The page of ``PATH`` (:class:`~nlosplan.reports.live.server.Page` without its token), or a one-line UserError."""
    from nlosplan.reports.live.design_watch import is_design_folder
    from nlosplan.reports.live.rig_watch import PLANNER, is_store
    from nlosplan.reports.live.server import Page

    p = Path(path)
    if not p.exists():
        raise UserError(f"{p} does not exist; give a design output folder or a capture store")
    if planner is not None and not Path(planner).is_dir():
        raise UserError(f"--planner {planner} is not a folder (give the 'rig run --out' folder)")
    if is_design_folder(p):
        if planner is not None or run is not None:
            raise UserError(f"{p} is a design output folder: --planner and --run belong to a capture store's page")
        return Page("design", p)
    if is_store(p):
        _check_store(p)
        return Page("rig", p, planner_dir=None if planner is None else Path(planner), run_id=run,
                    actions=planner is not None and not read_only)
    if p.is_dir() and (p / PLANNER).is_file():
        try:
            store = Path(json.loads((p / "rig_run.json").read_text(encoding="utf-8"))["store"])
        except (OSError, json.JSONDecodeError, KeyError, TypeError):
            raise UserError(f"{p} is a 'rig run' folder without rig_run.json (the run has not finished): "
                            f"give its store, nlosplan serve STORE --planner {p}") from None
        if not is_store(store):
            raise UserError(f"{p}/rig_run.json names the store {store}, which is not a capture store here: "
                            f"give it, nlosplan serve STORE --planner {p}")
        _check_store(store)
        return Page("rig", store, planner_dir=p, run_id=run, actions=not read_only)
    raise UserError(f"{p} is neither a design output folder (no design_checkpoint.json or "
                    "design_evaluations.jsonl) nor a capture store")


def _check_store(path) -> None:
    """A store opened once read-only with SQLite's quick check before it is served: a damaged one is one line."""
    from nlosplan.data.store import CaptureStore

    with CaptureStore(path, readonly=True, check=True):
        pass


def with_token(page, host: str, token: str | None, no_token: bool):
    """``page`` with the token actions need (a new random one by default); refuses a non-loopback host
    serving actions without a token."""
    from dataclasses import replace

    from nlosplan.reports.live.server import is_loopback

    if not page.actions:
        return replace(page, token=None)
    if no_token:
        if not is_loopback(host):
            raise UserError(f"--host {host} with --no-token would let anyone who reaches this machine move the "
                            "gantry: drop --no-token (the token is printed here), or add --read-only")
        return replace(page, token=None)
    return replace(page, token=token or secrets.token_urlsafe(16))


TOKEN_CHARS = re.compile(r"[A-Za-z0-9._~-]{8,256}")


def _poll(text: str) -> float:
    """``--poll S``: a finite number of seconds within :data:`~nlosplan.reports.live.server.POLL_RANGE_S`."""
    import argparse

    from nlosplan.reports.live.server import POLL_RANGE_S

    lo, hi = POLL_RANGE_S
    try:
        value = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a number") from None
    if not lo <= value <= hi:   # NaN fails too
        raise argparse.ArgumentTypeError(f"{text} is out of range; allowed: {lo:g} to {hi:g} seconds")
    return value


def read_token(token_arg: str | None, token_file: str | None, *, stdin=None) -> str | None:
    """The token actions need, from stdin (``--token -``) or a file (``--token-file PATH``); None: neither.

    A token on the command line (``--token VALUE``) is refused: every user of the machine can read it with
    ``ps``. The first line is the token (surrounding blanks dropped): 8 to 256 characters a URL carries as
    they are (letters, digits, ``. _ ~ -``). No message shows the token.

    Raises
    ------
    UserError
    """
    stdin = sys.stdin if stdin is None else stdin
    if token_arg is not None and token_arg != "-":
        raise UserError("--token VALUE on the command line can be read by every user of this machine (ps): "
                        "give --token - and type or pipe it on stdin, or --token-file PATH")
    if token_arg is not None and token_file is not None:
        raise UserError("--token - and --token-file exclude each other")
    if token_file is not None:
        try:
            with open(token_file, "rb") as fh:   # a pipe (--token-file <(pass show rig)) works too
                text = fh.read(4096).decode("utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            why = exc.strerror if isinstance(exc, OSError) and exc.strerror else "not UTF-8 text"
            raise UserError(f"--token-file {token_file}: cannot read it ({why})") from None
        where = f"--token-file {token_file}"
    elif token_arg == "-":
        if getattr(stdin, "isatty", lambda: False)():
            import getpass

            text = getpass.getpass("token (not shown): ")
        else:
            text = stdin.readline()
        where = "--token - (stdin)"
    else:
        return None
    lines = text.strip().splitlines()
    token = lines[0].strip() if lines else ""
    if not token:
        raise UserError(f"{where}: no token in it")
    if not TOKEN_CHARS.fullmatch(token):
        raise UserError(f"{where}: the token must have 8 to 256 characters, each a letter, a digit or one of . _ ~ -"
                        f" (this one has {len(token)} characters)")
    return token


def _cmd_serve(args) -> int:
    from nlosplan.reports.live.server import bind, is_loopback, page_url, parse_origin, serve, websocket_origins

    if (args.token is not None or args.token_file is not None) and args.no_token:
        raise UserError(f"{'--token' if args.token is not None else '--token-file'} and --no-token exclude each other")
    if args.token is not None and (args.token != "-" or args.token_file is not None):
        read_token(args.token, args.token_file)   # refused: a token in argv, or two sources
    for text in args.allow_origin:
        parse_origin(text, 1)                   # the syntax, before anything else
    page = resolve_page(args.path, planner=args.planner, run=args.run, read_only=args.read_only)
    if not page.actions and (args.token is not None or args.token_file is not None):
        raise UserError(f"{'--token' if args.token is not None else '--token-file'} applies only to a page with "
                        "actions: a store with --planner (or a 'rig run' folder), without --read-only")
    token = read_token(args.token, args.token_file)
    page = with_token(page, args.host, token, args.no_token)
    sock = bind(args.host, args.port)
    port = sock.getsockname()[1]
    allow = [parse_origin(text, port) for text in args.allow_origin]
    what = f"design page of {page.path}" if page.kind == "design" else f"rig page of {page.path}"
    print(f"nlosplan serve: {what} at {page_url(args.host, port, page.token)}  (Ctrl-C to stop)", file=sys.stderr,
          flush=True)
    if page.actions and page.token:
        print("nlosplan serve: approving, editing or refusing a batch needs the token in this URL; keep it private",
              file=sys.stderr, flush=True)
    if allow or not is_loopback(args.host):
        print("nlosplan serve: pages may connect from " + ", ".join(websocket_origins(args.host, port, allow))
              + " (add an address with --allow-origin HOST:PORT)", file=sys.stderr, flush=True)
    sig = serve(sock, page, poll_ms=max(1, round(1000 * args.poll)), allow_origins=allow)
    if sig is None:
        return 0
    import signal

    print(f"nlosplan serve: stopped ({signal.Signals(sig).name})", file=sys.stderr, flush=True)
    return 128 + int(sig)   # 143 after SIGTERM, 130 after Ctrl-C, as a shell reports a process a signal ended


def add(sub) -> None:
    """The ``serve`` subcommand."""
    p = sub_parser(sub, "serve", "serve", "live web page of a design folder or a capture store (finished or running)",
                   description=DESCRIPTION)
    p.add_argument("path", metavar="PATH", help="design output folder, capture store, or 'rig run --out' folder")
    p.add_argument("--planner", metavar="DIR", default=None,
                   help="with a store: the 'rig run --out' folder (route, RMSE, calibration, approval gate)")
    p.add_argument("--run", default=None, help="with a store: the run to show (default: the newest)")
    p.add_argument("--host", type=_host, default="127.0.0.1",
                   help="address to listen on (default: %(default)s, this machine only; 0.0.0.0: every interface)")
    p.add_argument("--port", type=int_type(0, 65535), default=DEFAULT_PORT,
                   help="TCP port (default: %(default)s; 0: any free port)")
    p.add_argument("--token", default=None, metavar="-",
                   help="'-': read the token actions need from stdin (typed, not shown, or piped); default: a new "
                        "random one, printed in the URL. A token given on the command line is refused (ps shows it)")
    p.add_argument("--token-file", default=None, metavar="PATH",
                   help="read the token from the first line of this file (keep it private: chmod 600)")
    p.add_argument("--no-token", action="store_true", help="actions without a token (only on a loopback --host)")
    p.add_argument("--allow-origin", action="append", default=[], metavar="HOST[:PORT]",
                   help="also let pages opened at this address talk to the server (repeatable; PORT: the one "
                        "served). Default: only the address served (every interface: the loopback names and this "
                        "machine's name); never a wildcard")
    p.add_argument("--read-only", action="store_true", help="no actions, whatever the store")
    p.add_argument("--poll", type=_poll, default=1.0, metavar="S",
                   help="seconds between reads of the files, 0.05 to 3600 (default: 1)")
    p.set_defaults(func=_cmd_serve)


__all__ = ["add", "read_token", "resolve_page", "with_token", "DEFAULT_PORT"]
