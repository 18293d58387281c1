"""The ``nlosplan`` command: argument parsing and calls into the rooms.

One module per subcommand (``sensor``, ``simulate``, ``check``, ``bench``,
``dataset``, ``benchmark``, ``study``, ``evaluate``);
each adds its parser and holds no logic beyond parsing and calling the rooms.
User errors (:class:`nlosplan.errors.UserError`, bad arguments) print one
line on stderr and exit with code 2; no traceback.
"""

from __future__ import annotations

import argparse
import sys

from nlosplan import __version__
import importlib

from nlosplan.cli.common import EXAMPLES, EXIT_USAGE, Parser, Terminated, examples
from nlosplan.errors import UserError
from nlosplan.resources import keep_freed_memory

__all__ = ["EXIT_USAGE", "ROOMS", "build_parser", "main"]

# The subcommand modules of ``nlosplan``, in the order of ``--help``; each has ``add(sub)``.
ROOMS: tuple[str, ...] = (
    "design",
    "sensor",
    "simulate",
    "check",
    "bench",
    "dataset",
    "benchmark",
    "study",
    "evaluate",
    "calibrate",
    "rig",
    "serve",
)


def build_parser() -> argparse.ArgumentParser:
    """The full ``nlosplan`` argument parser."""
    p = Parser(prog="nlosplan", formatter_class=argparse.RawDescriptionHelpFormatter,
                description="Sensor design and experiment planning for non-line-of-sight imaging "
                            "with low-cost flash dToF LiDARs (TMF8828 class).",
                epilog="examples:\n" + "\n".join(f"  {e}" for key in EXAMPLES for e in examples(key)))
    p.add_argument("--version", action="version", version=f"nlosplan {__version__}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=Parser)

    for name in ROOMS:
        importlib.import_module(f"nlosplan.cli.{name}").add(sub)
    return p


def main(argv: list[str] | None = None) -> int:
    """Entry point; returns the exit code.

    0: done; 2: a user error, one line on stderr (also when standard output cannot be written, e.g. a full
    disk); 130: interrupted (Ctrl-C, SIGINT); 143: terminated (SIGTERM, where a command takes it: the rig
    commands finalize on it as on Ctrl-C). Run as the program (``argv`` None), a Ctrl-C or SIGTERM that comes
    while Python shuts down after the work ends the process with 130/143, never 0.
    """
    if argv is not None:   # called in a program (tests): its stdout is left as it is
        return _main(argv)
    sys.stdout = _Stdout(sys.stdout)
    try:
        return _main(argv)
    finally:
        _late_signals()


class _Stdout:
    """Standard output that remembers a failed write (a full disk under it): said in one line, not at exit."""

    def __init__(self, inner):
        self._inner = inner
        self.failed: OSError | None = None

    def write(self, text):
        try:
            return self._inner.write(text)
        except OSError as exc:
            self.failed = exc
            raise

    def flush(self):
        try:
            return self._inner.flush()
        except OSError as exc:
            self.failed = exc
            raise

    def __getattr__(self, name):
        return getattr(self._inner, name)


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        keep_freed_memory()  # training and simulation loops reuse their freed arrays (see the function)
        func = getattr(args, "func", None)
        if func is None:
            raise UserError(f"give a command: {', '.join(ROOMS)} (see 'nlosplan --help')")
        code = int(func(args) or 0)
        sys.stdout.flush()   # a full disk under stdout fails here, with one line, not at exit
        return code
    except UserError as exc:
        print(f"nlosplan: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt as exc:   # a rig run says where it stopped and what finalize did
        if argv is None:               # the program: a second Ctrl-C while this line is written changes nothing
            _ignore_signals()
        what = "terminated (SIGTERM)" if isinstance(exc, Terminated) else "interrupted"
        print(f"nlosplan: {what}{': ' + str(exc) if str(exc) else ''}", file=sys.stderr)
        return 143 if isinstance(exc, Terminated) else 130
    except BrokenPipeError:  # output piped into e.g. `head`, which closed early
        _stdout_to_devnull()
        return 0
    except OSError as exc:
        failed = getattr(sys.stdout, "failed", None)
        if failed is None:
            raise
        _stdout_to_devnull()
        print(f"nlosplan: error: cannot write to standard output ({failed.strerror or failed}); files the command "
              "wrote are kept", file=sys.stderr)
        return EXIT_USAGE


def _stdout_to_devnull() -> None:
    """Point file descriptor 1 at /dev/null, so what is still buffered for it is dropped quietly at exit."""
    import os

    try:
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
    except (OSError, ValueError):
        pass


def _ignore_signals() -> None:
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)


def _late_signals() -> None:
    """After the command: SIGINT or SIGTERM during Python's shutdown (atexit hooks, threads) ends the process at
    once with 130 or 143; the outputs are written and the stores closed by then."""
    import os
    import signal
    import threading

    def now(signum, frame):
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(128 + signum)

    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            if signal.getsignal(sig) is not signal.SIG_IGN:
                signal.signal(sig, now)
