"""Shared pieces of the ``nlosplan`` command: the one-line-error parser, output, examples."""

from __future__ import annotations

import argparse
import json
import math
import sys
from contextlib import contextmanager
from typing import Callable

from nlosplan.errors import UserError
from nlosplan.progress import Progress
from nlosplan.resources import MAX_SEED
from nlosplan.schema import QUANTITIES, parse_int, parse_number, shown

EXIT_USAGE = 2
_INT_COLUMNS = ("position", "repeat")  # --where columns that take integers


def names_type(kind: str, allowed) -> Callable[[str], list[str]]:
    """An argparse type: a comma-separated list of names from ``allowed``."""

    def parse(text: str) -> list[str]:
        names = [v.strip() for v in text.split(",") if v.strip()]
        bad = [n for n in names if n not in allowed]
        if bad or not names:
            raise argparse.ArgumentTypeError(f"unknown {kind} {', '.join(bad) or '(none)'}; allowed: {', '.join(allowed)}")
        return list(dict.fromkeys(names))

    return parse


def _number(text: str, cast):
    """``text`` parsed strictly (ASCII digits only) as ``cast`` (int or float); ArgumentTypeError otherwise."""
    try:
        return parse_int(text) if cast is int else cast(parse_number(text))
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def number_type(cast, *, zero_ok: bool = False, hi: float | None = None) -> Callable[[str], float]:
    """An argparse type: a finite number > 0 (>= 0 with ``zero_ok``; at most ``hi`` when given).

    Written in ASCII digits (``1_0`` and other scripts' digits are refused). A flag named in
    :data:`FLAG_QUANTITIES` is also held to its physical range (see :class:`Parser`).
    """

    def parse(text: str):
        value = _number(text, cast)
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"{text} is not a finite number")
        if not (value >= 0 if zero_ok else value > 0):
            raise argparse.ArgumentTypeError(f"{text} must be {'>= 0' if zero_ok else '> 0'}")
        if hi is not None and value > hi:
            raise argparse.ArgumentTypeError(f"{text} is out of range; allowed: up to {hi:g}")
        return value

    return parse


def finite_float(text: str) -> float:
    """An argparse type: any finite number written in ASCII (what a bare ``type=float`` means here)."""
    value = _number(text, float)
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text} is not a finite number")
    return value


def strict_int(text: str) -> int:
    """An argparse type: an integer in ASCII digits (what a bare ``type=int`` means here)."""
    return _number(text, int)


#: Flags that set a physical quantity, and which one (:data:`nlosplan.schema.QUANTITIES`): every value of such a
#: flag, in every command, is held to that range when it is parsed, before any work.
FLAG_QUANTITIES = {
    "--jitter-ps": "jitter_fwhm_ps",
    "--bin-width-ps": "bin_width_ps",
    "--photon-scale": "photon_scale",
    "--settle": "settle_s",
    "--feed": "feed_mm_min",
    "--time-scale": "time_scale",
    "--limits": "gantry_mm",
    "--target-rmse": "target_rmse_m",
    "--object-albedo": "albedo",
    "--diffuse-albedo": "albedo",
    "--albedo": "albedo",
    "--wall-distance": "distance_m",
    "--distance": "distance_m",
    "--min-distance": "min_distance_m",
    "--object-size": "object_size_m",
    "--object-yaw": "angle_deg",
    "--yaw": "angle_deg",
    "--pitch": "angle_deg",
    "--samples": "wall_samples",
    "--seconds": "seconds",
    "--max-seconds": "budget_s",
    "--width": "model_width",
    "--threads": "threads",
}


#: Flags that name a file or folder: an empty value is refused when parsed (it would silently mean the current
#: folder, or nothing). So is an empty ``--out DIR`` (a folder; ``calibrate --out ''`` means no file).
PATH_FLAGS = ("--store", "--sensor", "--config", "--plan", "--rig-file", "--positions-json", "--real",
              "--pause-file", "--capture-sensor")


def _numbers(value):
    """The numbers in a parsed value (a number, or nested lists/tuples of them)."""
    if isinstance(value, (list, tuple)):
        for v in value:
            yield from _numbers(v)
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        yield value


def seed_type():
    """An argparse type: a random seed, 0 to :data:`~nlosplan.resources.MAX_SEED` (what every generator takes)."""
    return int_type(0, MAX_SEED)


def seed_list_type(max_count: int):
    """An argparse type: distinct seeds (each as :func:`seed_type`), comma-separated, at most ``max_count``."""
    one = seed_type()

    def parse(text: str) -> list[int]:
        seeds = [one(v.strip()) for v in text.split(",") if v.strip()]
        if not seeds:
            raise argparse.ArgumentTypeError("no seed given; e.g. 42,43,44")
        if len(set(seeds)) != len(seeds):
            raise argparse.ArgumentTypeError(f"seed {next(s for s in seeds if seeds.count(s) > 1)} given twice")
        if len(seeds) > max_count:
            raise argparse.ArgumentTypeError(f"{len(seeds)} seeds; at most {max_count}")
        return seeds

    return parse


def zones_type(text: str) -> tuple[int, int]:
    """An argparse type: a zone grid ``RxC`` (e.g. 3x3 or 8x8), 1 to 16 per axis."""
    from nlosplan.sensor_models.config import MAX_ZONES_PER_AXIS

    try:
        rows, cols = (parse_int(v) for v in text.lower().split("x"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{shown(text)} must look like 3x3 or 8x8 (rows x columns, ASCII digits)") \
            from None
    if not (1 <= rows <= MAX_ZONES_PER_AXIS and 1 <= cols <= MAX_ZONES_PER_AXIS):
        raise argparse.ArgumentTypeError(f"{text} is out of range; allowed: 1 to {MAX_ZONES_PER_AXIS} zones per axis")
    return rows, cols


class Terminated(KeyboardInterrupt):
    """SIGTERM as an interrupt (exit 143): the cleanups of Ctrl-C (a rig run's finalize) run for it too."""


@contextmanager
def sigterm_interrupts():
    """While the block runs, SIGTERM (a service manager's stop, ``kill``) raises :class:`Terminated` in the main
    thread, like Ctrl-C raises KeyboardInterrupt: what cleans up after Ctrl-C cleans up after it."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def stop(signum, frame):
        raise Terminated()

    old = signal.signal(signal.SIGTERM, stop)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, old)


def warn(message: str) -> None:
    """One ``nlosplan: warning: ...`` line on stderr (also with --json: stdout stays the result)."""
    print(f"nlosplan: warning: {message}", file=sys.stderr, flush=True)


def int_type(lo: int, hi: int | None = None):
    """An argparse type: an integer from ``lo`` to ``hi`` (no upper bound when None)."""

    def parse(text: str) -> int:
        n = _number(text, int)
        if n < lo or (hi is not None and n > hi):
            raise argparse.ArgumentTypeError(f"{n} is out of range; allowed: {lo} to {hi}" if hi is not None
                                             else f"{n} must be >= {lo}")
        return n

    return parse


def parse_where(text: str | None) -> dict:
    """``lights=off,zones=3x3,object=A|S`` as ``{"lights": "off", "zones": "3x3", "object": ["A", "S"]}``."""
    where: dict = {}
    for item in (text or "").split(","):
        if not item.strip():
            continue
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise UserError(f"--where {text!r}: each filter must look like column=value (alternatives a|b), "
                            "e.g. lights=off,zones=3x3")
        values = [v.strip() for v in value.split("|") if v.strip()]
        if key in _INT_COLUMNS:
            try:
                values = [parse_int(v) for v in values]
            except ValueError:
                raise UserError(f"--where {key}={value}: {key} takes integers") from None
        where[key] = values[0] if len(values) == 1 else values
    return where



class Parser(argparse.ArgumentParser):
    """ArgumentParser whose errors are one line and exit 2, and whose numbers are checked.

    A bare ``type=int`` or ``type=float`` reads ASCII digits only (and a float must be finite); a flag of
    :data:`FLAG_QUANTITIES` must lie within its physical range (every number of it, for a list or a pair); a
    flag of :data:`PATH_FLAGS` must not be empty.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.register("type", int, strict_int)
        self.register("type", float, finite_float)

    def _get_value(self, action, arg_string):  # noqa: D401 - argparse API: one value of one flag
        if arg_string == "" and (any(o in PATH_FLAGS for o in action.option_strings)
                                 or ("--out" in action.option_strings and action.metavar in ("DIR", "ROOT"))):
            raise argparse.ArgumentError(action, "give a path (it is empty)")
        value = super()._get_value(action, arg_string)
        names = [QUANTITIES[FLAG_QUANTITIES[o]] for o in action.option_strings if o in FLAG_QUANTITIES]
        for q in names[:1]:
            for v in _numbers(value):
                if not math.isfinite(v) or not q.contains(v):
                    raise argparse.ArgumentError(action, f"{arg_string if len(arg_string) <= 40 else f'{v:g}'} is "
                                                         f"out of range; allowed: {q.allowed()}")
        return value

    def format_help(self) -> str:
        """The help, where each flag of :data:`FLAG_QUANTITIES` says its range (``[allowed: 1 to 1e+06 ps]``)."""
        for action in self._actions:
            names = [o for o in action.option_strings if o in FLAG_QUANTITIES]
            if names and action.help and "[allowed:" not in action.help:
                action.help += f" [allowed: {QUANTITIES[FLAG_QUANTITIES[names[0]]].allowed()}]"
        return super().format_help()

    def error(self, message: str):  # noqa: D401 - argparse API
        raise UserError(f"{self.prog}: {message} (see '{self.prog} --help')")


def emit(args, data, text: str) -> None:
    if getattr(args, "json", False):
        print(json.dumps(data, indent=2, default=float))
    else:
        print(text)


EXAMPLES = {
    "design": (
        "nlosplan design                                   # the main job: DENALI preset, ~5 min on 2 cores",
        "nlosplan design --quick --json                    # reduced space, ~1 min",
        "nlosplan design --requirement 'loc<=0.03' --requirement 'size>=0.95@size=4in' --out out/d --resume",
        "nlosplan design --quick --out out/d --overwrite        # start over where out/d holds a previous run",
        "nlosplan design --config my_space.toml --cluster local:4",
    ),
    "serve": (
        "nlosplan serve nlosplan-out/design                # the design page (a run in progress or finished)",
        "nlosplan serve runs.db --planner nlosplan-out/rig-run   # the rig page; approve batches of 'rig run --approve'",
        "nlosplan serve runs.db --planner nlosplan-out/rig-run --token-file ~/.rig-token   # your token, not in ps",
        "nlosplan serve archive/denali.sqlite --host 0.0.0.0 --read-only --port 8060 --allow-origin rig-pc:8060",
    ),
    "sensor list": "nlosplan sensor list",
    "sensor show": "nlosplan sensor show tmf8828-3x3-short --json",
    "sensor fit-timebase": "nlosplan sensor fit-timebase ../shared/data/tmf882x_distance/distance_data_even.json",
    "simulate": (
        "nlosplan simulate --object A --size 8in --position 19 --lights off --out out/a19 --plot",
        "nlosplan simulate --scene corner --object-xy 0.45,0.30 --object A_8in --reflectance retroreflective "
        "--zones 8x8 --explain",
        "nlosplan simulate --scene wall --sensor tmf8828-8x8-short --distance 0.6 --yaw 20 --jitter-ps 100 "
        "--out out/wall --plot out/wall.png",
    ),
    "check": "nlosplan check --json",
    "bench histogram": "nlosplan bench histogram --json",
    "bench simulate": "nlosplan bench simulate --levels draft,low,default --reference-positions 0,45 --json",
    "dataset build": (
        "nlosplan dataset build --scene denali --store out/sim3x3.sqlite     # DENALI's calibrated unit and scene",
        "nlosplan dataset build --sensor tmf8828-3x3-short --store out/generic.sqlite   # the datasheet's unit",
        "nlosplan dataset build --objects A,S,circle --sizes 8in --positions 0-9,50-59 --lights on,off "
        "--repeats 3 --fidelity draft --seed 1 --store out/small.sqlite --json",
    ),
    "dataset import-denali": (
        "nlosplan dataset import-denali denali-data/data --store out/denali.sqlite",
        "nlosplan dataset import-denali denali-data/data --store out/denali.sqlite "
        "--positions-json denali/assets/tag1_positions.json",
    ),
    "dataset export-denali": "nlosplan dataset export-denali --store out/sim3x3.sqlite --out out/sim-denali "
                             "--zones 3x3 --lights off",
    "dataset info": "nlosplan dataset info --store out/denali.sqlite --by-object",
    "benchmark": (
        "nlosplan benchmark --store out/sim3x3.sqlite --where lights=off,zones=3x3 --out out/benchmark",
        "nlosplan benchmark --store out/denali.sqlite --where zones=3x3 --models mlp,cnn1d --tasks loc,shape "
        "--split positions --small --json",
    ),
    "study resolution": (
        "nlosplan study resolution --quick",
        "nlosplan study resolution --requirement 'loc<=0.03' --out out/resolution --json",
    ),
    "study bins": "nlosplan study bins --quick --out out/bins",
    "study jitter": (
        "nlosplan study jitter --store out/sim3x3.sqlite --where lights=off --out out/jitter",
        "nlosplan study jitter --store out/sim3x3.sqlite --small --jitter-ps 0,100,300,600 --models mlp,cnn1d,cnn3d "
        "--threads 2 --json",
        "nlosplan study jitter --denali denali-data/data --where lights=off --out out/jitter-real",
    ),
    "evaluate crlb": (
        "nlosplan evaluate crlb --objects A,S --sizes 4in,8in --positions 0-99 --repeats 3",
        "nlosplan evaluate crlb --objects A --positions 0-9 --nuisance photon_scale,ambient --lights on "
        "--fidelity draft --json",
        "nlosplan evaluate crlb --sensor tmf8828-8x8-short --objects shapes --positions 0,45,99 --jitter-ps 300",
    ),
    "evaluate observer": (
        "nlosplan evaluate observer shape --objects all --size 8in --draws 100",
        "nlosplan evaluate observer size --objects letters --positions 0-9 --photon-scale 0.1 --fidelity draft --json",
        "nlosplan evaluate observer shape --objects A,S,circle --position-known --rule max --seed 1",
    ),
}


def examples(key: str) -> tuple[str, ...]:
    """The example command lines of a (sub)command."""
    value = EXAMPLES[key]
    return value if isinstance(value, tuple) else (value,)


def sub_parser(subparsers, name: str, key: str, help_text: str, description: str | None = None) -> argparse.ArgumentParser:
    lines = examples(key)
    head = "example:" if len(lines) == 1 else "examples:"
    return subparsers.add_parser(name, help=help_text, description=description or help_text,
                                 epilog=head + "\n" + "\n".join(f"  {e}" for e in lines),
                                 formatter_class=argparse.RawDescriptionHelpFormatter)


def command_group(sub, name: str, help_text: str, description: str, metavar: str = "SUBCOMMAND"):
    """A subcommand that holds subcommands (``nlosplan NAME SUB ...``); returns the holder for :func:`sub_parser`."""
    group = sub.add_parser(name, help=help_text, description=description)
    holder = group.add_subparsers(dest=f"{name}_command", metavar=metavar, parser_class=Parser)

    def usage(args) -> int:  # `nlosplan NAME` alone: one line naming the subcommands (help with --help)
        raise UserError(f"nlosplan {name}: give a {metavar.lower()}: {', '.join(holder.choices)} "
                        f"(see 'nlosplan {name} --help')")

    group.set_defaults(func=usage)
    return holder


@contextmanager
def progress_bar(args, total: int | None, desc: str, unit: str):
    """Progress of long work on stderr (:class:`nlosplan.progress.Progress`): a tqdm bar on a terminal, a line
    every few seconds otherwise, also with --json; nothing with --quiet. Closed on exit."""
    with Progress(desc, total, unit, enabled=not getattr(args, "quiet", False)) as bar:
        yield bar


def note(args, message: str) -> None:
    """One line on stderr before long work, only for a person watching a terminal (not with --json)."""
    if not args.json and sys.stderr.isatty():
        print(message, file=sys.stderr, flush=True)

