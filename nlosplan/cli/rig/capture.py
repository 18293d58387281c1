"""``nlosplan rig capture|dry-run|status``: run capture plans on the rig (or on pty emulators), dry runs, run status."""

from __future__ import annotations

import argparse
import hashlib
import json
import math
from contextlib import contextmanager
from pathlib import Path

from nlosplan.cli.common import emit, int_type, number_type, progress_bar, seed_type, sigterm_interrupts
from nlosplan.errors import UserError
from nlosplan.schema import check_quantity, parse_int, parse_number

EXAMPLES = {
    "capture": (
        "nlosplan rig capture --lidar /dev/ttyACM0 --gantry /dev/ttyUSB0 --plan raster --repeats 3 "
        "--object A --size 8in --lights off --store runs.db",
        "nlosplan rig capture --emulate --plan raster --positions 0-9 --repeats 3 --store out/emu.db --json",
        "nlosplan rig capture --emulate --plan positions.csv --zones 8x8 --store out/emu.db "
        "--emulate-faults garble=40,drop=300",
        "nlosplan rig capture --emulate lidar --gantry /dev/ttyUSB0 --home --positions 0-9 --store out/gantry.db",
        "nlosplan rig capture --lidar /dev/ttyACM0 --gantry /dev/ttyACM1 --gantry-kind telemetrix "
        "--rig-file denali-telemetrix.toml --store runs.db",
    ),
}
FAULT_KEYS = {"garble": "garble_every", "truncate": "truncate_every", "drop": "drop_every",
              "disconnect": "disconnect_after_frames", "slow": "slow_answer_s", "alarm": "alarm_on_move",
              "slow-ok": "slow_ok_s"}


def _sub(rsub, name: str, help_text: str, description: str | None = None) -> argparse.ArgumentParser:
    lines = EXAMPLES[name]
    return rsub.add_parser(name, help=help_text, description=description or help_text,
                           epilog="examples:\n" + "\n".join(f"  {e}" for e in lines),
                           formatter_class=argparse.RawDescriptionHelpFormatter)


def _range_list(text: str) -> list[int]:
    out: list[int] = []
    for part in text.split(","):
        part = part.strip()
        if not part:
            continue
        lo, sep, hi = part.partition("-")
        try:
            a, b = parse_int(lo), parse_int(hi) if sep else parse_int(lo)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r}: use grid indices like 0-9,20,45") from None
        if not (0 <= a <= b <= 99):
            raise argparse.ArgumentTypeError(f"{part!r}: grid indices run from 0 to 99")
        out += range(a, b + 1)
    if not out:
        raise argparse.ArgumentTypeError("give at least one grid index")
    return list(dict.fromkeys(out))


def _limits(text: str):
    try:
        (x0, x1), (y0, y1) = [tuple(parse_number(v) for v in axis.split(":")) for axis in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r}: use XMIN:XMAX,YMIN:YMAX in mm, e.g. 0:320,0:320") from None
    if not all(math.isfinite(v) for v in (x0, x1, y0, y1)):
        raise argparse.ArgumentTypeError(f"{text[:60]!r}: each value must be a finite number of mm")
    if not (x0 < x1 and y0 < y1):
        raise argparse.ArgumentTypeError(f"{text!r}: each minimum must be below its maximum")
    return (x0, x1), (y0, y1)


def _faults(text: str) -> dict:
    out = {}
    for item in text.split(","):
        if not item.strip():
            continue
        key, _, val = item.partition("=")
        if key.strip() not in FAULT_KEYS:
            raise argparse.ArgumentTypeError(f"unknown fault {key[:40]!r}; allowed: {', '.join(FAULT_KEYS)}")
        seconds = FAULT_KEYS[key.strip()] in ("slow_answer_s", "slow_ok_s")
        try:
            v = parse_number(val)
        except ValueError:
            raise argparse.ArgumentTypeError(f"fault {key}={val[:40]!r} needs a number") from None
        hi = 3600 if seconds else 10**9
        if not (math.isfinite(v) and 0 <= v <= hi) or (not seconds and v != int(v)):
            raise argparse.ArgumentTypeError(f"fault {key}={val[:40]} is out of range; allowed: "
                                             + (f"0 to {hi} s" if seconds else f"a whole number from 0 to {hi}"))
        out[FAULT_KEYS[key.strip()]] = v
    return out


def _run_name(text: str) -> str:
    """An argparse type: a run id (it names the captures' ``capture_id``): 1 to 200 printable characters, no '/'."""
    if not text or len(text) > 200 or "/" in text or not text.isprintable() or text != text.strip():
        raise argparse.ArgumentTypeError(f"{text[:40]!r}: a run id is 1 to 200 printable characters without '/' or "
                                         "spaces around it (leave --run out for one derived from the plan)")
    return text


def add_motion_options(p: argparse.ArgumentParser) -> None:
    """--repeats, --settle, --limits, --feed (shared by the rig subcommands that move the gantry)."""
    p.add_argument("--repeats", type=int_type(1, 1000), default=3, help="captures per position (default: 3)")
    p.add_argument("--settle", type=number_type(float, zero_ok=True), default=0.5, metavar="S",
                   help="seconds to wait after each move (default: 0.5)")
    p.add_argument("--limits", type=_limits, default=((0.0, 320.0), (0.0, 320.0)), metavar="X0:X1,Y0:Y1",
                   help="gantry soft limits in mm (default: 0:320,0:320)")
    p.add_argument("--feed", type=number_type(float), default=3000.0, help="feed rate, mm/min (default: 3000)")


def add_mode_options(p: argparse.ArgumentParser) -> None:
    """--zones and --range of the TMF8828."""
    p.add_argument("--zones", default="3x3", choices=["3x3", "4x4", "8x8"], help="TMF8828 zones (default: 3x3)")
    p.add_argument("--range", dest="range_mode", default="short", choices=["short", "long"],
                   help="ranging mode (default: short)")


def _plan_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("--plan", default="raster", metavar="raster|FILE",
                   help="'raster' (DENALI's 10x10 snake) or a positions file (CSV/text 'x_mm,y_mm' lines, or JSON)")
    p.add_argument("--positions", type=_range_list, default=None, metavar="0-9,45",
                   help="raster only: these grid indices, in this order (default: all 100)")
    add_motion_options(p)
    p.add_argument("--object", default="A", help="hidden object label (default: A)")
    p.add_argument("--size", default="8in", help="object size label (default: 8in)")
    add_mode_options(p)
    p.add_argument("--sensor", default=None, metavar="NAME|FILE",
                   help="sensor model of the captures and of the direct-view check "
                        "(default: the tmf8828-<zones>-<range> preset)")
    p.add_argument("--json", action="store_true", help="machine-readable output")


def _build_plan(args):
    """(plan factory, description, spec, total captures)."""
    from nlosplan.hardware.plans import positions_plan, raster_plan, read_positions

    if args.plan == "raster":
        positions = args.positions or list(range(100))
        spec = {"kind": "raster", "positions": positions, "repeats": args.repeats, "settle_s": args.settle}
        desc = f"raster {len(positions)} positions x {args.repeats}"

        def factory():
            return raster_plan(repeats=args.repeats, settle_s=args.settle, positions=positions)
    else:
        if args.positions is not None:
            raise UserError("--positions selects raster grid indices; with a positions file, edit the file")
        points = read_positions(args.plan)
        spec = {"kind": "positions", "points": [list(p) for p in points], "repeats": args.repeats,
                "settle_s": args.settle}
        desc = f"{Path(args.plan).name}: {len(points)} positions x {args.repeats}"

        def factory():
            return positions_plan(points, repeats=args.repeats, settle_s=args.settle)
    return factory, desc, spec, len(spec.get("positions") or spec.get("points")) * args.repeats


def _view_check(args):
    from nlosplan.hardware.executor import view_problem
    from nlosplan.hardware.rig import sensor_preset

    if getattr(args, "sensor_config", None) is not None:
        cfg = args.sensor_config
    else:
        cfg = sensor_preset(args.zones, args.range_mode)
    from nlosplan.denali import DENALI_OBJECTS

    obj = args.object if args.object in DENALI_OBJECTS else "A"
    return lambda x, y: view_problem(cfg, obj, args.size if args.size in ("4in", "8in") else "8in", x, y)


def _dry(args, factory, controller=None):
    from nlosplan.hardware.executor import dry_run

    return dry_run(factory(), limits_mm=args.limits, feed_mm_min=args.feed,
                   view=None if args.no_view_check else _view_check(args), controller=controller)


def _sensor_config(args):
    """The ``--sensor`` model (its zones must be ``--zones``), or the mode's preset."""
    from nlosplan.hardware.rig import sensor_preset

    if args.sensor is None:
        return sensor_preset(args.zones, args.range_mode)
    from nlosplan.sensor_models import resolve_sensor

    cfg = resolve_sensor(args.sensor)
    if f"{cfg.zones_rows}x{cfg.zones_cols}" != args.zones or cfg.n_bins != 128:
        raise UserError(f"--sensor {args.sensor!r} has {cfg.zones_rows}x{cfg.zones_cols} zones and {cfg.n_bins} bins; "
                        f"the TMF8828 in --zones {args.zones} gives {args.zones} zones and 128 bins")
    return cfg


def _run_id(args, spec: dict) -> str:
    if args.run:
        return args.run
    blob = json.dumps({"spec": spec, "object": args.object, "size": args.size, "lights": args.lights,
                       "zones": args.zones, "range": args.range_mode,
                       "emulated": True if args.emulate == "both" else (args.emulate or False)}, sort_keys=True)
    kind = spec["kind"]
    return f"{kind}-{args.object}-{args.size}-{args.lights}-{args.zones}-{hashlib.sha256(blob.encode()).hexdigest()[:8]}"


def _cmd_capture(args) -> int:
    from nlosplan.hardware.executor import Executor, RunContext
    from nlosplan.data.store import CaptureStore

    devices = resolve_devices(args, seed_is_noise=True)
    args.sensor_config = _sensor_config(args)
    factory, desc, spec, total = _build_plan(args)
    rep = _dry(args, factory)
    if rep.problems:
        raise UserError(f"nothing moved: the plan has {len(rep.problems)} problem(s); first: {rep.problems[0]} "
                        "(see 'nlosplan rig dry-run')")
    run_id = _run_id(args, spec)
    ctx = RunContext(args.object, args.size, class_group=args.class_group, lights=args.lights == "on",
                     source="emulated:rig" if "lidar" in devices["emulate"] else "rig", plan=desc,
                     plan_total=total, plan_spec=spec)
    pause = (lambda: Path(args.pause_file).exists()) if args.pause_file else None
    from nlosplan.cli.live import live_page

    with sigterm_interrupts(), live_page(args, "rig", args.store, run_id=run_id), \
            rig_failures(run_id, args.store) as hold, \
            CaptureStore(args.store) as store, _open(args, devices, store=store, run_id=run_id) as rig, \
            progress_bar(args, total, f"rig {run_id}", "capture") as bar:
        ex = hold["executor"] = Executor(rig, store, run_id=run_id, context=ctx, check_view=not args.no_view_check,
                                         on_capture=(lambda r: bar.update(1)) if bar is not None else None,
                                         pause_when=pause)
        summary = ex.run(factory())
    data = {"store": str(args.store), **summary.to_dict()}
    text = (f"run {run_id}: {summary.captured} captured, {summary.resumed} already stored, {summary.moves} moves, "
            f"{summary.retries} retries in {summary.seconds:.1f} s -> {args.store}\n"
            f"sensor: {summary.sensor_stats.get('frames', 0)} frames read, "
            f"{summary.sensor_stats.get('dropped_frames', 0)} dropped, "
            f"{summary.sensor_stats.get('garbage_lines', 0)} garbage lines\nfinalize: {'; '.join(summary.finalize)}")
    emit(args, data, text)
    return 0


@contextmanager
def rig_failures(run_id: str, store_path):
    """One line (exit 2) for whatever ends a rig run: a device failure at open or during the run, a full disk.

    Ctrl-C stays an interrupt (exit 130) with the same line. Each line says what finalize did (sensor stopped?
    gantry parked? where?). Yields a dict: put the :class:`Executor` under ``"executor"`` once the rig is open.
    """
    import errno
    import sqlite3

    from nlosplan.hardware.rig import device_errors

    hold: dict = {}

    def where() -> str:
        ex = hold.get("executor")
        if ex is None:
            return "the rig did not open: nothing moved, nothing was captured"
        s = ex.summary
        return (f"stopped at step {max(s.steps - 1, 0)}: {s.captured} new captures stored ({s.resumed} found "
                f"stored); finalize: {'; '.join(s.finalize) or 'not run'}")

    try:
        yield hold
    except UserError as exc:
        if hold.get("executor") is None:
            raise
        raise UserError(f"run {run_id} {where()}: {exc}") from None
    except device_errors() as exc:
        hint = "rerun the same command to resume"
        if type(exc).__name__ == "GrblAlarm":
            hint = "clear the cause and rerun the same command with --unlock or --home to resume"
        raise UserError(f"run {run_id}: {exc}; {where()}; {hint}") from None
    except (sqlite3.Error, OSError) as exc:
        full = "full" in str(exc) or getattr(exc, "errno", None) in (errno.ENOSPC, errno.EDQUOT)
        what = (f"capture store {store_path}: {exc}" if isinstance(exc, sqlite3.Error) or full
                else f"{type(exc).__name__}: {exc}")
        todo = "free space and rerun the same command to resume" if full else "rerun the same command to resume"
        raise UserError(f"run {run_id}: {what}{' (disk full; the captures committed before are kept)' if full else ''}"
                        f"; {where()}; {todo}") from None
    except KeyboardInterrupt as exc:   # Ctrl-C, or SIGTERM as Terminated (exit 143): said the same way
        raise type(exc)(f"run {run_id} {where()}; rerun the same command to resume") from None


def _faults_for(kind: str, faults: dict):
    from nlosplan.hardware.emulators import GantryFaults, SensorFaults

    cls = SensorFaults if kind == "lidar" else GantryFaults
    floats = {"slow_answer_s", "slow_ok_s"}
    got = {k: (v if k in floats else int(v)) for k, v in faults.items() if k in cls.__dataclass_fields__}
    return cls(**got) if got else None


def resolve_devices(args, *, seed_is_noise: bool) -> dict:
    """Which device is real (on which port) and which emulated; every flag that does not apply is refused.

    ``--emulate`` alone means both devices; ``--emulate lidar`` or ``--emulate gantry`` one of them.
    """
    emulate = {"both": ("lidar", "gantry"), "lidar": ("lidar",), "gantry": ("gantry",), None: ()}[args.emulate]
    if not emulate and not (args.lidar or args.gantry):
        raise UserError("give --lidar PORT and --gantry PORT, or --emulate")
    for dev in ("lidar", "gantry"):
        port = getattr(args, dev)
        if dev in emulate and port:
            raise UserError(f"--{dev} {port} and --emulate {args.emulate} both name the {dev}: drop one")
        if dev not in emulate and not port:
            raise UserError(f"give --{dev} PORT for the real {dev}, or --emulate {dev} (or --emulate for both)")
    if args.baud is not None and "lidar" in emulate:
        raise UserError("--baud is the real TMF8828's baud rate; the emulated sensor needs none")
    if args.time_scale is not None and "gantry" not in emulate:
        raise UserError("--time-scale speeds up an emulated gantry; the gantry here is real")
    if seed_is_noise and args.seed is not None and "lidar" not in emulate:
        raise UserError("--seed seeds the emulated sensor's noise; the sensor here is real")
    faults = getattr(args, "emulate_faults", None) or {}
    sensor_keys = {k for k in faults if k in ("garble_every", "truncate_every", "drop_every",
                                              "disconnect_after_frames", "slow_answer_s")}
    if faults and not emulate:
        raise UserError("--emulate-faults needs --emulate")
    if sensor_keys and "lidar" not in emulate:
        raise UserError(f"--emulate-faults {', '.join(sorted(sensor_keys))}: sensor faults need an emulated sensor")
    if set(faults) - sensor_keys and "gantry" not in emulate:
        raise UserError("--emulate-faults alarm/slow-ok are gantry faults and need an emulated gantry")
    kind = args.gantry_kind
    if kind == "auto" and "gantry" in emulate:
        raise UserError("--gantry-kind auto probes a real port; with an emulated gantry say grbl or telemetrix")
    if args.rig_file and kind == "grbl":
        raise UserError("--rig-file describes a Telemetrix gantry; add --gantry-kind telemetrix (or auto)")
    if kind == "telemetrix" and (args.home or args.unlock):
        raise UserError("--home and --unlock are GRBL's; a Telemetrix gantry has no limit switches and no alarm lock")
    if kind == "telemetrix" and args.work_offset != "auto":
        raise UserError("--work-offset is GRBL's; a Telemetrix gantry's origin is origin_mm in its --rig-file")
    from nlosplan.hardware.telemetrix_config import load_rig_file

    return {"emulate": emulate, "lidar": args.lidar, "gantry": args.gantry, "gantry_kind": kind,
            "telemetrix": load_rig_file(args.rig_file) if args.rig_file else None,
            "work_offset": _work_offset(args.work_offset),
            "sensor_faults": _faults_for("lidar", faults), "gantry_faults": _faults_for("gantry", faults)}


def _work_offset(text):
    """``--work-offset``: auto, keep or X,Y in mm, each within the gantry's range (before anything connects)."""
    from nlosplan.hardware.grbl_frame import parse_work_offset

    if str(text).strip().lower() in ("auto", "keep"):
        return parse_work_offset(text)
    parts = str(text).split(",")
    try:
        xy = tuple(parse_number(v) for v in parts)
    except ValueError:
        xy = ()
    if len(xy) != 2:
        raise UserError(f"--work-offset {text[:40]!r}: use auto, keep, or X,Y in mm (e.g. -320,-320)")
    return tuple(check_quantity("gantry_mm", v, f"--work-offset {axis}") for axis, v in zip("XY", xy))


@contextmanager
def _open(args, devices: dict, *, store=None, run_id: str | None = None):
    """The rig of the command line (:func:`nlosplan.hardware.rig.rig_session`), a context manager.

    With a store and run id the session is checked and recorded (:func:`nlosplan.cli.rig.origin.origin_session`):
    a gantry that counts from where the carriage stands needs it at the origin before anything moves.
    """
    from nlosplan.cli.rig.origin import origin_session
    from nlosplan.hardware.lights import FixedLights
    from nlosplan.hardware.rig import RigOptions, rig_session

    park = None if args.no_park else (args.limits[0][0], args.limits[1][0])
    with rig_session(RigOptions(**devices, zones=args.zones, range_mode=args.range_mode,
                                baudrate=args.baud or 2_000_000, sensor_config=args.sensor_config,
                                limits_mm=args.limits, feed_mm_min=args.feed, lights=FixedLights(args.lights == "on"),
                                lights_on=args.lights == "on", home=args.home, unlock=args.unlock, park_mm=park,
                                obj=args.object, size=args.size, seed=args.seed or 0,
                                time_scale=args.time_scale or 20.0)) as rig:
        if store is None:
            yield rig
        else:
            with origin_session(args, rig, store, run_id):
                yield rig


def add_device_options(p: argparse.ArgumentParser, *, seed_help: str) -> None:
    """The devices: real ports or emulators, the gantry's kind and set-up (shared by capture and run)."""
    p.add_argument("--lidar", metavar="PORT", help="TMF8828 serial port (or pyserial URL)")
    p.add_argument("--gantry", metavar="PORT", help="gantry serial port (or pyserial URL)")
    p.add_argument("--emulate", nargs="?", const="both", default=None, choices=["lidar", "gantry", "both"],
                   help="pty emulators (same driver code): alone both devices, or only 'lidar' or 'gantry' "
                        "(the other one real)")
    p.add_argument("--gantry-kind", default="grbl", choices=["grbl", "telemetrix", "auto"],
                   help="gantry firmware: GRBL 1.1, Telemetrix4Arduino (DENALI's rig), or auto (probe which "
                        "answers) (default: grbl)")
    p.add_argument("--rig-file", default=None, metavar="TOML",
                   help="Telemetrix gantry: pins, steps/mm, speed, acceleration, flips, origin "
                        "(default: DENALI's values; see docs/rig-connect.md)")
    p.add_argument("--work-offset", default="auto", metavar="auto|keep|X,Y",
                   help="GRBL: how plan coordinates map onto machine coordinates: auto (G54 set so the limits fit "
                        "GRBL's machine space), keep (the controller's active offset) or X,Y (G54, mm) "
                        "(default: auto)")
    p.add_argument("--baud", type=int, default=None, choices=[115200, 1_000_000, 2_000_000],
                   help="real TMF8828's firmware baud rate (default: 2000000, DENALI's)")
    p.add_argument("--home", action="store_true", help="GRBL: home the gantry ($H) before the run")
    p.add_argument("--unlock", action="store_true",
                   help="GRBL: clear an alarm with $X (after ALARM:1/2 a soft reset first); only if you know "
                        "where it is")
    from nlosplan.cli.rig.origin import ORIGIN_HELP

    p.add_argument("--origin-confirmed", action="store_true", help=ORIGIN_HELP)
    p.add_argument("--seed", type=seed_type(), default=None, help=seed_help)
    p.add_argument("--time-scale", type=number_type(float), default=None,
                   help="emulated gantry: motion runs this much faster (default: 20)")


def add(sub):
    """The ``rig`` group with ``capture``; returns the group's subparsers (the other commands add themselves)."""
    from nlosplan.cli.common import command_group

    rsub = command_group(sub, "rig", "drive the capture rig (TMF8828 + GRBL or Telemetrix gantry), or emulators",
                         "Drive the capture rig: a TMF8828 on the ams Arduino firmware and a gantry on GRBL 1.1 or "
                         "Telemetrix4Arduino, or, with --emulate, pty emulators of either or both (the sensor's "
                         "backed by the fast simulator). Set-up and every error: docs/rig-connect.md.")
    c = _sub(rsub, "capture", "run a capture plan, every capture stored once (rerun the same command to resume)",
             CAPTURE_DESCRIPTION)
    add_device_options(c, seed_help="emulated sensor: noise seed (default: 0)")
    c.add_argument("--store", required=True, help="capture store (SQLite; created when missing)")
    c.add_argument("--run", type=_run_name, default=None,
                   help="run id (default: derived from the plan and labels, so a rerun resumes)")
    _plan_options(c)
    c.add_argument("--class-group", default=None, help="class group of a non-DENALI object")
    c.add_argument("--lights", default="off", choices=["on", "off"], help="room lights during the run (default: off)")
    c.add_argument("--no-park", action="store_true",
                   help="do not park the gantry at the end (at the limits' minimum; a gantry that counts from where "
                        "the port opened, Telemetrix or GRBL without homing, at that origin)")
    c.add_argument("--no-view-check", action="store_true",
                   help="skip the check that the object never enters the LiDAR's direct view (DENALI geometry)")
    c.add_argument("--pause-file", default=None, metavar="PATH",
                   help="pause at the next position while this file exists")
    c.add_argument("--emulate-faults", type=_faults, default=None, metavar="K=V,...",
                   help=f"--emulate: inject faults ({', '.join(FAULT_KEYS)}), e.g. garble=40,drop=300,disconnect=5")
    from nlosplan.cli.live import add_live_option

    add_live_option(c, "the run (rig map, last histograms, captures, faults)")
    c.set_defaults(func=_cmd_capture)
    return rsub


CAPTURE_DESCRIPTION = """\
Run a capture plan on the rig and store every capture (one SQLite transaction
each, with run id, step, commanded and reported gantry position in the plan's
frame plus the controller's raw position, sensor and firmware configuration,
timestamps, lights, repeat). The plan is checked dry first (limits, object
never in the LiDAR's direct view) and the gantry's own limits at open (GRBL's
machine space and work offset); nothing moves if a check fails. The sensor is
stopped and the gantry parked at the end, also on errors, Ctrl-C (exit 130)
and SIGTERM (exit 143), and the last line says so. Rerunning the same command resumes the run: stored captures
are skipped, nothing is taken twice. A lost sensor link is reconnected and the
frame retried; a gantry alarm ends the run (clear it, rerun with --unlock or
--home). --emulate runs both devices as pty emulators (DENALI scene, fast
simulator) driven by the same code, --emulate lidar or --emulate gantry one of
them; emulated motion runs --time-scale times faster. A gantry that counts from
where the carriage stood when the port opened (Telemetrix; GRBL without homing)
parks at that origin, and when the store's last session did not end there the
run asks to confirm the carriage is at the origin (--origin-confirmed) before
it moves. docs/rig-connect.md: set-up and every error line."""
