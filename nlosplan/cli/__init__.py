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

from nlosplan.cli.common import EXAMPLES, EXIT_USAGE, Parser, examples
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
    """Entry point; returns the exit code."""
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        keep_freed_memory()  # training and simulation loops reuse their freed arrays (see the function)
        func = getattr(args, "func", None)
        if func is None:
            raise UserError(f"give a command: {', '.join(ROOMS)} (see 'nlosplan --help')")
        return int(func(args) or 0)
    except UserError as exc:
        print(f"nlosplan: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt as exc:   # a rig run says where it stopped and what finalize did
        print(f"nlosplan: interrupted{': ' + str(exc) if str(exc) else ''}", file=sys.stderr)
        return 130
    except BrokenPipeError:  # output piped into e.g. `head`, which closed early
        import os

        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
        return 0

